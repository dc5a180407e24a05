"""Real-like data to tune ``hindrax ident fit`` on, and the figures it gives: piloted and closed-loop
virtual-pool bags with what real pool days have and the vehicle file does not.

Four data sets of :mod:`.ident_fit` (same bag generator, :mod:`hindrax_sim.piloted_bag`, the
command through the thrust allocation to the simulated thrusters and sensors), all on Hindrax:

* ``realdata_piloted``: the setpoint pilot; ``realdata_closedloop``: the survey autopilot (integral action against
  the tether and the current, little excitation); ``realdata_openloop``: few long open-loop runs (held levels), a
  0.25 s transport delay, per-thruster thrust 0.7-1.3 of the curve and a gyro ten times noisier (issue 72's
  vehicle B, four bags fitted and four predicted); ``realdata_vehicle_b``: as vehicle B's data show it, 22 runs of
  60 s (11 fitted) with idle stretches, levels up to the saturation, a DVL at 4 Hz losing a fifth of its reports, a
  gyro bias and the current changing within a run;
* tether drift: a tether whose pull changes from run to run (anchor and tension) under a current that drifts over
  four minutes; per-run bias: each bag gets its own tether lay and current offset (``DataSet.runs``), so the force
  that moves a vehicle at rest differs between runs;
* coupling through the allocation: the eight thrusters each deliver their own fraction of the curve's thrust
  (0.85-1.08, ``disturbances.thrust.per_thruster``), so a command in one DOF leaks into the others;
* an unknown deadband: the ESCs' 45 us where the vehicle file says 25 us (small commands give no thrust);
* a slow yaw response: three times the vehicle file's yaw added mass and half its linear damping.

The first three bags of each set are fitted (no vehicle file, as on another vehicle's data), the other two are
predicted; per DOF the held-out NRMSE of the fit, of the independent gray-box 1-DOF model (:mod:`.graybox`, the
model the fit must not lose to by more than :data:`NESTED_MARGIN`), of a plain least squares and of holding the
velocity (:func:`.ident_fit.evaluate`), the cross-validated scores, the verdict (never worse than persistence)
and whether the delay sat at its bound.

Usage: ``python -m hindrax_tools.benchmarks.ident_realdata [--keep DIR] [--only NAME,...]
[--results-doc docs/results.md]``: prints the table; with ``--results-doc`` writes section ``ident-realdata`` of that
document (``ident-realdata-openloop`` for ``--only realdata_openloop``: one section per choice) and its figure
``figures/ident_realdata.png`` (``ident_realdata_openloop.png``) next to it. Tune on this, never on the tests."""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import matplotlib
import numpy as np

from hindrax_tools import results_doc

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .ident_fit import DOFS_COMPARED, DataSet, evaluated  # noqa: E402

#: Largest held-out NRMSE of the fit above the gray-box 1-DOF model's that still meets the target
NESTED_MARGIN = 0.005

_TRUTH = {
    "thrusters": {"time_constant_s": 0.15, "deadband_us": 45.0},
    "esc": {"output_latency_s": 0.03},
    "hydrodynamics": {"yaw": {"added_mass_kg_m2": 1.65, "linear_damping_kg_m2_s": 0.74}},
    "disturbances": {
        "thrust": {"per_thruster": [1.0, 0.9, 1.05, 0.85, 1.08, 0.95, 0.9, 1.0], "negative": 0.85},
        "current": {"velocity_ned_m_s": [0.02, 0.01, 0.0], "amplitude_ned_m_s": [0.02, 0.015, 0.0], "period_s": 240.0},
        "tether": {"anchor_ned_m": [5.0, 0.0, 0.0], "attachment_frd_m": [-0.25, 0.0, -0.1],
                   "drag_n_s2_m3": 2.0, "tension_n": 0.8},
        "dvl": {"latency_s": 0.05},
    },
}
#: what changes between runs: the tether's lay and pull, the current's offset
_RUNS = (
    {"disturbances": {"tether": {"anchor_ned_m": [5.0, 0.0, 0.0], "tension_n": 0.4},
                      "current": {"velocity_ned_m_s": [0.02, 0.01, 0.0]}}},
    {"disturbances": {"tether": {"anchor_ned_m": [0.0, 4.0, 0.0], "tension_n": 1.5},
                      "current": {"velocity_ned_m_s": [-0.01, 0.02, 0.0]}}},
    {"disturbances": {"tether": {"anchor_ned_m": [2.0, -3.0, 1.0], "tension_n": 0.9},
                      "current": {"velocity_ned_m_s": [0.03, -0.01, 0.0]}}},
    {"disturbances": {"tether": {"anchor_ned_m": [6.0, 2.0, 0.0], "tension_n": 1.2},
                      "current": {"velocity_ned_m_s": [0.0, 0.0, 0.0]}}},
    {"disturbances": {"tether": {"anchor_ned_m": [-1.0, 1.0, 0.0], "tension_n": 0.6},
                      "current": {"velocity_ned_m_s": [0.015, 0.02, 0.0]}}},
)

DATASETS: tuple[DataSet, ...] = (
    DataSet("realdata_piloted", {}, _TRUTH, {"actuation": "thrusters", "sensors": "dvl", "duration_s": 150.0},
            seed=4600, runs=_RUNS,
            note="setpoints; tether drift and per-run tether/current; per-thruster thrust 0.85-1.08; deadband 45 us "
                 "(file 25); yaw added mass x3, linear damping /2"),
    DataSet("realdata_closedloop", {}, _TRUTH, {"actuation": "thrusters", "sensors": "dvl", "pilot": "autopilot",
                                                "duration_s": 150.0, "jitter": 0.1},
            seed=4700, runs=_RUNS,
            note="survey autopilot; the same vehicle and disturbances"),
    # what vehicle B showed (issue 72): few long open-loop runs, a transport delay of 0.25 s, a thrust model tens of
    # percent off per thruster, a noisy gyro
    DataSet("realdata_openloop", {}, {**_TRUTH, "thrusters": {"time_constant_s": 0.05},
                                      "disturbances": {**_TRUTH["disturbances"], "thrust": {
                                          "per_thruster": [1.25, 0.8, 1.2, 0.75, 1.3, 0.85, 0.7, 1.15],
                                          "negative": 0.75}},
                                      "simulation": {"sensors": {"icm20948_gyro": {"noise_std_rad_s": 0.03}}}},
            {"actuation": "thrusters", "sensors": "dvl", "pilot": "openloop", "duration_s": 60.0, "delay_s": 0.25,
             "jitter": 0.0}, seed=4800, train=4, holdout=4, runs=_RUNS,
            note="open-loop held levels, 60 s runs; delay 0.25 s; per-thruster thrust 0.7-1.3, reverse 0.75; gyro "
                 "noise 0.03 rad/s"),
    # vehicle B as its data show it (issue 72): 22 open-loop runs of 60 s, 11 fitted; idle stretches; levels up to
    # the saturation; a DVL at 4 Hz losing a fifth of its reports; a gyro with bias and noise; the current (and so
    # the tether's drag) changing within a run
    DataSet("realdata_vehicle_b", {}, {**_TRUTH, "thrusters": {"time_constant_s": 0.05, "deadband_us": 45.0},
                                       "disturbances": {**_TRUTH["disturbances"], "thrust": {
                                           "per_thruster": [1.25, 0.8, 1.2, 0.75, 1.3, 0.85, 0.7, 1.15],
                                           "negative": 0.75},
                                           "current": {"velocity_ned_m_s": [0.02, 0.01, 0.0],
                                                       "amplitude_ned_m_s": [0.04, 0.03, 0.0], "period_s": 50.0},
                                           "imu": {"gyro_bias_walk_rad_s_sqrt_s": 0.002}},
                                       "simulation": {"sensors": {
                                           "icm20948_gyro": {"noise_std_rad_s": 0.03, "bias_rad_s": 0.01},
                                           "dvl75": {"rate_hz": 4.0, "dropout_probability": 0.2}}}},
            {"actuation": "thrusters", "sensors": "dvl", "pilot": "openloop", "duration_s": 60.0, "delay_s": 0.25,
             "jitter": 0.0, "level_top": 1.0, "idle_fraction": 0.35}, seed=5000, train=11, holdout=11, runs=_RUNS,
            note="as realdata_openloop, 22 runs (11 fitted); idle stretches 4-12 s; levels up to the saturation; "
                 "DVL 4 Hz with 20 % dropouts; gyro bias 0.01 rad/s and its walk; current changing within a run"),
)


def run(only: list[str] | None = None, keep: str | None = None) -> dict:
    """{data set name: {"note", "bags_s", "fit_s", dof: row of :func:`.ident_fit.evaluate`}}."""
    return {data.name: {"note": data.note, "bags_s": bags_s, "fit_s": fit_s, **{d: res[d] for d in DOFS_COMPARED}}
            for data, bags_s, fit_s, res in evaluated(DATASETS, only, keep, gray_box=True)}


def _f(x) -> str:
    return "-" if x is None or not math.isfinite(float(x)) else f"{float(x):.3f}"


def table_rows(res: dict) -> list[list]:
    """One Markdown row per data set and DOF."""
    rows = []
    for name, r in res.items():
        for dof in DOFS_COMPARED:
            x = r[dof]
            gb = x.get("gray_box", math.nan)
            met = "yes" if x["fit"] <= gb + NESTED_MARGIN else "no" if math.isfinite(gb) else "-"
            rows.append([name, dof, _f(x["fit"]), _f(gb), met, _f(x["ls"]), _f(x["hold"]), _f(x.get("floor")),
                         _f(x.get("cv")), _f(x.get("cv_hold")), x.get("verdict", x["status"]),
                         x.get("model", "") + (" (delay at its bound)" if x.get("at_edge") else "")])
    return rows


HEADER = ["data set", "DOF", "held-out nrmse fit", "gray-box 1-DOF", f"fit <= gray-box + {NESTED_MARGIN}",
          "least squares", "hold", "noise floor", "CV fit", "CV hold", "verdict", "model chosen by CV; delay, lag s"]


def figure(res: dict, path: Path) -> Path:
    """Bar chart of the held-out NRMSE (fit, gray-box, least squares, hold, noise floor) per data set and DOF."""
    names = list(res)
    fig, axes = plt.subplots(1, len(names), figsize=(5.5 * len(names), 3.4), squeeze=False)
    for ax, name in zip(axes[0], names):
        x = np.arange(len(DOFS_COMPARED))
        for k, (key, label) in enumerate((("fit", "hindrax ident fit"), ("gray_box", "gray-box 1-DOF"),
                                          ("ls", "plain least squares"), ("hold", "hold the velocity"),
                                          ("floor", "noise floor"))):
            vals = [res[name][d].get(key, math.nan) for d in DOFS_COMPARED]
            ax.bar(x + (k - 2) * 0.16, np.minimum(np.nan_to_num(vals, nan=0.0), 2.0), 0.16, label=label)
        ax.set_xticks(x, DOFS_COMPARED)
        ax.set_ylim(0, 2.0)
        ax.set_ylabel("held-out nrmse (10 s open loop)")
        ax.set_title(name)
        ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (``argv`` without the program name); returns the exit code."""
    p = argparse.ArgumentParser(prog="python -m hindrax_tools.benchmarks.ident_realdata",
                                description=__doc__.splitlines()[0])
    p.add_argument("--only", default="", help="comma-separated data sets: " + ", ".join(d.name for d in DATASETS))
    p.add_argument("--keep", default=None, help="directory for the bags (reused on the next run)")
    results_doc.add_argument(p)
    a = p.parse_args(argv)
    only = [n for n in a.only.split(",") if n]
    res = run(only or None, a.keep)
    print(results_doc.markdown_table(HEADER, table_rows(res)))
    if a.results_doc:  # a section of its own per --only choice: the other sets' tables stay
        section = "-".join(["ident-realdata"] + [n.removeprefix("realdata_") for n in only])
        doc = Path(a.results_doc)
        png = figure(res, doc.parent / "figures" / f"{section.replace('-', '_')}.png")
        def made(r):
            return "bags reused from --keep" if r["bags_s"] < 5 else f"{r['bags_s']:.0f} s of bags"

        notes = "\n".join(f"- `{n}` ({made(r)}, {r['fit_s']:.0f} s to fit and evaluate): {r['note']}"
                          for n, r in res.items())
        body = ("The first bags of a set fitted, the others predicted, no vehicle file; held-out nrmse = "
                "RMS(predicted - measured) / std(measured) of 10 s open-loop predictions from the measured velocity "
                "(`python -m hindrax_tools.benchmarks.ident_realdata`). Gray-box 1-DOF: "
                "M v' = u - k_l v - k_q |v| v - b with a delayed, lagged command, fitted by simulation error, delay "
                "and lag chosen by leave-one-run-out cross-validation on the fitted bags "
                "(`hindrax_tools.benchmarks.graybox`, independent of the fit).\n\n"
                + notes + "\n\n"
                + results_doc.markdown_table(HEADER, table_rows(res))
                + f"\n\n![held-out nrmse per data set and DOF]({png.relative_to(doc.parent).as_posix()})\n")
        results_doc.write_if_asked(a, section, "Identification on real-like data" + (f" ({', '.join(only)})"
                                                                                     if only else ""), body)
    return 0


if __name__ == "__main__":
    sys.exit(main())
