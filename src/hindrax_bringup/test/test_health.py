"""The verdict of ``hindrax health`` (hindrax_bringup/layout/health.py): every launched node present, its status OK, the
supervisor OK; everything else listed."""
from __future__ import annotations

from pathlib import Path

from hindrax_bringup.layout.health import Seen, assess, expectation
from hindrax_bringup.layout.launch_xml import read_launch

REPO = Path(__file__).resolve().parents[3]
#: the vehicle's nodes in launch order (static TF shares the sensor drivers' process, last; the allocation the
#: ESC's, allocation first)
VEHICLE = ["dvl75", "ping1d", "ms5837", "icm20948", "static_tf", "thrust_allocation", "esc", "supervisor",
           "output_guard", "gateway"]
STATUSES = ["hindrax/dvl75", "hindrax/ping1d", "hindrax/ms5837", "hindrax/icm20948", "hindrax/esc_pca9685",
            "hindrax/supervisor", "hindrax/output_guard"]
OK = Seen(0, "running")


def test_expectation_follows_the_launch_file_and_its_arguments():
    path = REPO / "src/hindrax_bringup/launch/vehicle.launch.xml"
    share = lambda pkg: REPO / "src" / pkg  # noqa: E731
    plain = expectation(n for p in read_launch(path, {}, share) for n in p.node_names)
    assert plain.nodes == tuple(VEHICLE) and plain.statuses == tuple(STATUSES) and plain.supervisor
    recorded = expectation(n for p in read_launch(path, {"record": "true"}, share) for n in p.node_names)
    assert recorded.nodes[-1] == "recorder" and recorded.statuses[-1] == "recorder: recording"


def test_ready_when_every_node_and_status_is_there_and_ok():
    expect = expectation(VEHICLE)
    report = assess(expect, ["/" + n for n in VEHICLE] + ["/hindrax_health"], {s: OK for s in STATUSES}, OK)
    assert report.ready and not report.problems and len(report.ok) == len(VEHICLE) + len(STATUSES) + 1
    assert report.summary().startswith("READY")


def test_each_missing_or_failing_item_is_one_line():
    expect = expectation(VEHICLE)
    statuses = {s: OK for s in STATUSES}
    statuses["hindrax/dvl75"] = Seen(2, "cannot open /dev/hindrax-dvl: No such file or directory; retrying")
    statuses["hindrax/ping1d"] = Seen(1, "connected to /dev/hindrax-ping, no data")
    del statuses["hindrax/esc_pca9685"]
    report = assess(expect, [n for n in VEHICLE if n != "static_tf"], statuses, Seen(2, "depth 31.0 m > 30.0 m"))
    assert not report.ready
    assert report.problems == [
        "node static_tf missing",
        "hindrax/dvl75: ERROR cannot open /dev/hindrax-dvl: No such file or directory; retrying",
        "hindrax/esc_pca9685: no status received",
        "supervisor/status: ERROR depth 31.0 m > 30.0 m"]
    assert report.warnings == ["hindrax/ping1d: WARN connected to /dev/hindrax-ping, no data"]
    assert report.summary().startswith("NOT READY: 4 problem(s): node static_tf missing; ")
    # --strict: the warning is a problem too; no supervisor status at all is a problem
    strict = assess(expect, VEHICLE, {s: (Seen(1, "no data") if s == "hindrax/ping1d" else OK) for s in STATUSES},
                    None, strict=True)
    assert strict.problems == ["hindrax/ping1d: WARN no data", "supervisor/status: no status received"]
    assert assess(expect, VEHICLE, {s: Seen(3, "stale") for s in STATUSES}, OK).problems[0] == \
        "hindrax/dvl75: STALE stale"
