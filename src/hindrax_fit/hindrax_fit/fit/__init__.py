"""The offline fit: the per-DOF model, the fit core, the priors' posterior, the thrust calibration, the readers."""
