"""``identification.*``: the campaign and its estimators (docs/architecture.md §5; [Hindrax-Drag] §4)."""
from __future__ import annotations

from typing import Any, Mapping

from ..spec import ConfigIssue, flag, integer, real, section, text

SCHEMA, OPTIONAL = section("identification", {
    "levels_per_dof": integer("thrust levels in each DOF's ladder", 1, 50),
    "level_fraction_min": real("smallest level as a fraction of the DOF's authority", 0.01, 1.0),
    "level_fraction_max": real("largest level as a fraction of the DOF's authority", 0.01, 1.0),
    "forgetting_factor": real("RLS forgetting factor lambda", 0.9, 1.0),
    "estimate_rate_hz": real("RLS update rate, Hz", 1.0, 400.0),
    "command_rate_hz": real("manoeuvre wrench command rate, Hz: the control law steps at estimate_rate_hz and "
                            "its wrench is sent and held at this rate (a whole fraction of estimate_rate_hz; "
                            "default estimate_rate_hz)", 1.0, 400.0),
    "publish_rate_hz": real("HydroEstimate publication rate, Hz", 0.1, 50.0),
    "altitude_setpoint_m": real("altitude held during manoeuvres, m ([Hindrax-Drag] §4: 0.8-1.0 m)", 0.1, 50.0),
    "roll_test_angle_rad": real("roll test turns back at this angle, rad ([Hindrax-Drag] §4.2: 30 deg)", 0.01, 1.5),
    "pitch_test_angle_rad": real("pitch test turns back at this angle, rad ([Hindrax-Drag] §4.2: 40 deg)", 0.01, 1.5),
    "max_level_duration_s": real("longest time one level is held, s", 1.0, 600.0),
    "heave_repeats": integer("down/up pairs of runs at each heave level of the ladder, default 3",
                             1, 10),
    "converged_relative_std": real("converged when every std/|value| is below this", 0.001, 1.0),
    "prior_std_rel": real("1-sigma of the empirical priors in the batch fit, as a fraction of the prior "
                          "value (0 = no prior; docs/identification.md §6.3)", 0.0, 100.0),
    "rls_directional_forgetting": flag("online RLS: forget only along the regressor (Bittanti et al. "
                                       "1990), default true (docs/identification.md §1.D)"),
    "rls_min_excitation": real("online RLS: hold the estimate while the normalised excitation is below "
                               "this once reached (0 = no gate), default 0.001", 0.0, 1.0),
    "rls_change_threshold": real("online RLS: reset the covariance when the mean normalised a-priori error "
                                 "over rls_change_window_s exceeds this (0 = no detector), default 6",
                                 0.0, 1e6),
    "rls_change_window_s": real("online RLS: window of the change detector, s, default 10", 0.1, 600.0),
    "rls_prior_std_rel": real("online RLS: 1-sigma of its starting values (empirical priors) as a "
                              "fraction of the prior value (0 = diffuse start at zero), default 1",
                              0.0, 100.0),
    "excitation": text("force input per DOF: the constant-thrust ladder, or one broadband run shaped to "
                       "stay in the pool box (hindrax_onboard identification/online/excitation.py)",
                       ("ladder", "multisine", "prbs", "chirp")),
    "excitation_duration_s": real("length of the broadband run per DOF (excitation not ladder), s", 5.0, 1800.0),
}, optional=("excitation", "prior_std_rel", "rls_", "command_rate_hz", "heave_repeats"))


def cross_checks(c: Mapping[str, Any]) -> list[ConfigIssue]:
    """The ladder's smallest level at most its largest; the command rate a whole fraction of the estimate rate
    (1, 1/2, 1/3, ... of it: a command is held for a whole number of control ticks)."""
    a, b = "identification.level_fraction_min", "identification.level_fraction_max"
    out = [ConfigIssue(a, c[a], f"at most {b} ({c[b]:g})")] if a in c and b in c and c[a] > c[b] else []
    k, e = "identification.command_rate_hz", "identification.estimate_rate_hz"
    if c.get(k) is not None and e in c:
        ratio = c[e] / c[k]
        if ratio < 1.0 - 1e-9 or abs(ratio - round(ratio)) > 1e-6:
            out.append(ConfigIssue(k, c[k], f"{e} ({c[e]:g}) divided by a whole number (1, 2, 3, ...)"))
    return out
