"""Issue "Main job" item 9, the pipeline part: a shortened campaign (surge and heave) through the whole ROS graph
in one process (simulator, device emulators, drivers, ESC node, allocation, identification node, recorder),
armed through esc/set_armed, driven by the run_identification action, identified offline from the recorded bag.

Checks: the action succeeds for both DOFs with online estimates; identification.yaml and the report are written
from the bag; the bag exists and replays (the recorded messages decode); the vehicle ends disarmed with neutral
pulse widths; the offline estimates are finite with positive inertia and damping.
NOT checked here: the identification tolerances (5 %, 0.2 N). Through the graph they are not met yet (measured:
surge inertia -5 %, heave quadratic damping about x2); the in-process campaign meets them
(src/hindrax_ident/test/test_identification_accuracy.py). Tracked on the issues.
"""
import math

import pytest

from hindrax_drivers.config import default_config_path, load_config
from hindrax_drivers.recording.reader import BagReader
from hindrax_ident.identification.graph_campaign import run_graph_campaign
from hindrax_ident.identification.results import read_identification

pytestmark = pytest.mark.ros


def test_surge_and_heave_through_the_graph(tmp_path):
    cfg = load_config(default_config_path())
    outcome = run_graph_campaign(default_config_path(), tmp_path, dofs=("surge", "heave"), levels=2, seed=1,
                                 real_time_factor=0.0, deadline_s=900)
    assert outcome.success, outcome.message
    assert outcome.errors == {} and set(outcome.identifications) == {"surge", "heave"}
    for dof, r in outcome.identifications.items():
        for name, value in r.values.items():
            assert math.isfinite(value), f"{dof} {name} = {value}"
        assert r.values["inertia"] > cfg.mass_kg  # rigid mass plus a positive added mass
        assert all(v > 0 for k, v in r.values.items() if k.startswith("quadratic_damping"))
    # the online RLS estimates came back in the action result
    assert {e.dof for e in outcome.estimates} == {"surge", "heave"}
    # outputs: identification.yaml (validated on read) naming the bag, and the report
    doc = read_identification(tmp_path / "identification.yaml")
    assert set(doc["dofs"]) == {"surge", "heave"} and doc["provenance"]["bag"].endswith("bag")
    assert (tmp_path / "report" / "index.html").is_file()
    # the bag exists, has its metadata and replays: every message of every topic decodes
    assert (tmp_path / "bag" / "metadata.yaml").is_file()
    reader = BagReader(tmp_path / "bag")
    assert {"/dvl/data", "/thrusters/pulse_width", "/identification/status", "/raw/dvl75"} <= set(reader.topics)
    n = sum(1 for _ in reader.decoded(["/dvl/data", "/identification/status", "/wrench"]))
    assert n > 1000
    # disarmed at the end, outputs neutral
    assert outcome.disarmed
    assert outcome.final_pulse_width_us == pytest.approx([1500.0] * 8, abs=1.3)
