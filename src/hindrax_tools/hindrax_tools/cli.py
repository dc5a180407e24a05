"""The topside's ``hindrax`` commands: :data:`TOPSIDE`, added to the vehicle's command line
(:mod:`hindrax_onboard.cli`, which owns the ``hindrax`` script) through the ``hindrax.commands`` entry point of
setup.py. :data:`COMMANDS` is every command of a topside install; ``python -m hindrax_tools.cli`` runs ``hindrax``."""
from __future__ import annotations

import sys

from hindrax_onboard.cli import COMMANDS as VEHICLE
from hindrax_onboard.cli import build_parser, main

__all__ = ["COMMANDS", "TOPSIDE", "build_parser", "main"]

_T = "hindrax_tools.commands"
#: (command words, module implementing add_arguments/run, one-line help) of the topside's commands
TOPSIDE: list[tuple[tuple[str, ...], str, str]] = [
    (("allocate",), f"{_T}.allocate",
     "allocate a base_link wrench X Y Z K M N (N, N m) to thruster forces and pulse widths (JSON)"),
    (("bringup",), f"{_T}.bringup",
     "the virtual pool's single-process graph (--sim); the vehicle runs the launch file instead"),
    (("ident", "free-decay"), f"{_T}.ident",
     "added mass from a free-decay CSV (time s, acceleration m/s^2), [Hindrax-AM] eqs. 2-9 (JSON)"),
    (("ident", "thruster-fit"), f"{_T}.ident",
     "thrust-curve cubics from bollard-pull CSV, [Hindrax-Drag] eq. 1 (JSON; --write CONFIG)"),
    (("ident", "priors"), f"{_T}.ident",
     "empirical added mass and damping priors from geometry, [NTNU-Thesis] App. A.1/A.2 (JSON)"),
    (("ident", "inclining"), f"{_T}.ident",
     "roll/pitch restoring stiffness from an inclining test CSV with a known mass (JSON)"),
    (("ident", "tilt-decay"), f"{_T}.ident",
     "rigid + added roll/pitch inertia from a free-decay CSV and the inclining stiffness (JSON)"),
    (("ident", "campaign"), f"{_T}.ident", "the campaign in-process (`hindrax run --in-process`)"),
    (("ident", "scenarios"), f"{_T}.scenarios",
     "scenario suite: in-process campaigns on named truth files; error, z, coverage, verdicts"),
    (("ident", "start"), f"{_T}.ident_live",
     "send the identification campaign to a running stack, print its feedback; Ctrl-C cancels"),
    (("ident", "status"), f"{_T}.ident_live", "where a running campaign is (identification/status)"),
    (("ident", "continue"), f"{_T}.ident_live",
     "tell a running campaign's calibration step that the operator did what its prompt asked"),
    (("ident", "bag"), f"{_T}.ident_bag",
     "offline identification of a recorded campaign bag: identification.yaml + report"),
    (("ident", "fit"), f"{_T}.ident_fit",
     "identify from any bag, validated (K-fold, holdout): identification.yaml + report"),
    (("ident", "predict"), f"{_T}.ident_predict",
     "open-loop predictions of an identification.yaml on bags: one CSV per bag and DOF, nrmse"),
    (("run",), f"{_T}.run", "identification campaign on the virtual pool through the ROS graph"),
    (("control", "evaluate"), f"{_T}.control",
     "closed-loop holds in the virtual pool: identified model vs vehicle file vs the PD hold"),
    (("control", "scenarios"), f"{_T}.control",
     "per scenario truth: identify in-process, then compare the holds of the two models"),
    (("control", "hold"), f"{_T}.control_hold",
     "the running controller holds a depth or an altitude and the heading, or where it is"),
    (("control", "release"), f"{_T}.control_hold", "the running controller lets go (zero wrench)"),
    (("control", "model"), f"{_T}.control", "the controller's gains and the source of each model value"),
    (("pool", "rehearse"), f"{_T}.pool",
     "the README's pool day on a laptop: the live pool, the installed launch, the shells' env"),
]
#: every command of a topside install: the vehicle's and :data:`TOPSIDE`
COMMANDS = VEHICLE + TOPSIDE

if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
