"""The per-DOF model the online campaign and the topside fit share: regressors, priors' posterior, record, topic."""
