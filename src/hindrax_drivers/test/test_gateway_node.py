"""The gateway process refuses a bad setting at start-up with one line naming key, value and allowed range."""
import subprocess
import sys
from pathlib import Path

import pytest

from hindrax_drivers.testing import child_env

CONFIG = Path(__file__).resolve().parents[3] / "ros_ws" / "config" / "hindrax.yaml"


@pytest.mark.parametrize("setting, line", [
    ("topside_domain_id:=500", "invalid configuration: topside_domain_id = 500: allowed integer in [0, 101]"),
    ("topside_discovery_range:=WIDE", "topside_discovery_range = 'WIDE': allowed one of LOCALHOST, SUBNET"),
    ("call_timeout_s:=0.0", "call_timeout_s = 0.0: allowed number in [0.1, 30]"),
    ("vehicle.name:=a-b", "vehicle.name = 'a-b': allowed a ROS name token"),
])
def test_bad_setting_stops_the_start_in_one_line(setting, line):
    r = subprocess.run([sys.executable, "-m", "hindrax_drivers.gateway.node", "--ros-args", "--params-file",
                        str(CONFIG), "-p", setting], capture_output=True, text=True, env=child_env(), timeout=60)
    assert r.returncode == 1
    errors = [x for x in r.stderr.splitlines() if x.startswith("invalid configuration")]
    assert len(errors) == 1 and line in errors[0], r.stderr


def test_feedback_that_overtakes_the_acceptance_is_relayed_and_the_goal_runs_on():
    """On the internal side a running goal's first feedback can reach the gateway before its acceptance (the action
    client's feedback callback runs before the send-goal future's): the topside goal is relayed that feedback and
    ends with the internal result, never read as refused."""
    import itertools
    from types import SimpleNamespace

    from action_msgs.msg import GoalStatus
    from rclpy.serialization import serialize_message

    from hindrax_drivers.gateway.node import Gateway
    from hindrax_msgs.action import RunIdentification

    feedback = RunIdentification.Feedback(dof="surge", level_index=0, level_count=1)
    result = RunIdentification.Result(success=True, message="done")
    gw = SimpleNamespace(verifier=SimpleNamespace(check_message=lambda *_: ""),
                         bounds=SimpleNamespace(goal_problem=lambda _g: ""), _ids=itertools.count(1), _goals={},
                         settings=SimpleNamespace(call_timeout_s=1.0), _action_type=RunIdentification,
                         campaign=SimpleNamespace(context=SimpleNamespace(ok=lambda: True)), _refuse=lambda w, *_: w)

    def send(head, payload=b""):
        if head["k"] == "goal":
            q = gw._goals[head["id"]]
            q.put(({"k": "feedback", "id": head["id"]}, serialize_message(feedback)))
            q.put(({"k": "accepted", "id": head["id"], "ok": True, "why": ""}, b""))
            q.put(({"k": "result", "id": head["id"], "status": GoalStatus.STATUS_SUCCEEDED},
                   serialize_message(result)))

    gw.channel = SimpleNamespace(send=send)
    seen = []
    handle = SimpleNamespace(request=RunIdentification.Goal(dofs=["surge"]), is_cancel_requested=False,
                             publish_feedback=seen.append, succeed=lambda: seen.append("succeeded"),
                             abort=lambda: seen.append("aborted"), canceled=lambda: seen.append("canceled"))
    out = Gateway._run_goal(gw, handle)
    assert out.success and out.message == "done"
    assert [type(x).__name__ if not isinstance(x, str) else x for x in seen] == [
        "RunIdentification_Feedback", "succeeded"]
