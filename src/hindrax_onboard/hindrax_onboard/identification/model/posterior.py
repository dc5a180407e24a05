"""The empirical priors applied to one DOF's fit: the Gaussian update shared by ``hindrax ident bag`` and ``hindrax
ident fit`` (docs/identification.md §6.3 and §7 step 6).

The fit core's estimate theta_fit (p,) with covariance C (p, p) is a Gaussian measurement of the parameters; the
empirical priors ([NTNU-Thesis] App. A.1/A.2 through :func:`~hindrax_onboard.estimation.priors.priors_from_config`)
are independent Gaussians N(mu_i, sd_i^2) on some of them. The posterior ([Tarantola2005] Ch. 3, eqs. 3.37-3.38
for a linear problem) is

    P = C^-1 + D,   theta = P^-1 (C^-1 theta_fit + D mu),   cov = P^-1,

D = diag(1 / sd_i^2) on the parameters with a prior (0 elsewhere): the no-calibration case of
:func:`~.calibration.joint_estimate`, which calls it then. Units: those of the parameters."""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from hindrax_common.config import DOFS, or_default

from ...estimation.least_squares import EstimationError
from ...estimation.priors import priors_from_config
from .dof_model import rigid_inertia

__all__ = ["DEFAULT_PRIOR_STD_REL", "finite_or_none", "prior_std_rel_of", "prior_entries",
           "theta_priors", "prior_posterior"]

#: Default 1-sigma of an empirical prior as a fraction of the prior's value (``identification.prior_std_rel``).
DEFAULT_PRIOR_STD_REL = 0.5


def prior_std_rel_of(cfg, prior_std_rel: float | None = None) -> float:
    """``prior_std_rel`` or the vehicle file's ``identification.prior_std_rel`` (default
    :data:`DEFAULT_PRIOR_STD_REL`); raises ``ValueError`` when negative or not finite."""
    if prior_std_rel is None:
        prior_std_rel = float(or_default(cfg.identification.prior_std_rel, DEFAULT_PRIOR_STD_REL))
    if not (math.isfinite(prior_std_rel) and prior_std_rel >= 0):
        raise ValueError(f"prior_std_rel must be >= 0, got {prior_std_rel}")
    return float(prior_std_rel)


def finite_or_none(x) -> float | None:
    """``x`` as a float, None for None, NaN or inf (JSON and YAML have no NaN)."""
    return None if x is None or (isinstance(x, float) and not math.isfinite(x)) else float(x)


def prior_entries(cfg) -> dict[str, dict]:
    """Per DOF ``{added_mass, linear_damping, quadratic_damping, source}``: the empirical priors from the
    configured geometry ([NTNU-Thesis] App. A.1/A.2, :func:`~hindrax_onboard.estimation.priors.priors_from_config`;
    no projected areas in the vehicle file, so a solid prism: an upper bound). A value that cannot be computed is
    None; ``{}`` if the configuration lacks the geometry."""
    try:
        p = priors_from_config(cfg)
    except (KeyError, TypeError, EstimationError):
        return {}
    src = "[NTNU-Thesis] App. A.1/A.2 empirical estimate, solid prism of the configured box"
    keys = ("added_mass", "linear_damping", "quadratic_damping")
    return {dof: {**{k: finite_or_none(p[k][i]) for k in keys}, "source": src} for i, dof in enumerate(DOFS)}


def theta_priors(dof: str, names: Sequence[str], cfg, prior_std_rel: float) -> dict[str, tuple[float, float]]:
    """{parameter: (mean, std)} of the empirical priors on the physical parameters: inertia = rigid + prior added mass
    with std ``prior_std_rel`` x the added mass (the rigid part is known), quadratic and linear damping (heave: the
    same prior for both directions, and for one pair of both) with std ``prior_std_rel`` x the value. Bias,
    restoring, cross-coupling and the reverse thrust gain have none."""
    if not prior_std_rel > 0:
        return {}
    p = prior_entries(cfg).get(dof)
    if not p:
        return {}
    out = {}
    for n in names:
        key = ("added_mass" if n == "inertia" else "quadratic_damping" if n.startswith("quadratic")
               else "linear_damping" if n.startswith("linear") else None)
        val = p.get(key) if key else None
        if val is None or not (math.isfinite(val) and val > 0):
            continue
        mean = val + (rigid_inertia(cfg, dof) if n == "inertia" else 0.0)
        out[n] = (float(mean), float(prior_std_rel) * float(val))
    return out


def prior_posterior(names: Sequence[str], theta, cov, priors: dict[str, tuple[float, float]]
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(theta (p,), cov (p, p)) after the priors {name: (mean, std)} (module docstring). A parameter with zero fit
    variance (a term the model leaves out, fixed at 0) keeps its value and zero variance; ``theta`` and ``cov``
    unchanged when no prior applies."""
    theta = np.asarray(theta, dtype=float)
    cov = np.asarray(cov, dtype=float)
    cov = 0.5 * (cov + cov.T)
    idx = [i for i, n in enumerate(names) if n in priors and cov[i, i] > 0]
    if not idx:
        return theta.copy(), cov.copy()
    free = np.flatnonzero(np.diag(cov) > 0)
    c = cov[np.ix_(free, free)]
    info = np.linalg.pinv(c, hermitian=True)  # a singular fit covariance (a collinear pair) raises nothing
    d = np.zeros(free.size)
    mu = np.zeros(free.size)
    for j, i in enumerate(free):
        if i in idx:
            m, sd = priors[names[i]]
            d[j], mu[j] = 1.0 / sd ** 2, m
    post = np.linalg.inv(info + np.diag(d))
    post = 0.5 * (post + post.T)
    th = theta.copy()
    th[free] = post @ (info @ theta[free] + d * mu)
    out = np.zeros_like(cov)
    out[np.ix_(free, free)] = post
    return th, out
