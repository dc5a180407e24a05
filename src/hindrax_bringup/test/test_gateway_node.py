"""The gateway process refuses a bad setting at start-up with one line naming key, value and allowed range."""
import subprocess
import sys
from pathlib import Path

import pytest

from hindrax_common.testing import child_env

CONFIG = Path(__file__).resolve().parents[3] / "ros_ws" / "config" / "hindrax.yaml"


@pytest.mark.parametrize("setting, line", [
    ("topside_domain_id:=500", "invalid configuration: topside_domain_id = 500: allowed integer in [0, 101]"),
    ("topside_discovery_range:=WIDE", "topside_discovery_range = 'WIDE': allowed one of LOCALHOST, SUBNET"),
    ("call_timeout_s:=0.0", "call_timeout_s = 0.0: allowed number in [0.1, 30]"),
    ("vehicle.name:=a-b", "vehicle.name = 'a-b': allowed a ROS name token"),
])
def test_bad_setting_stops_the_start_in_one_line(setting, line):
    r = subprocess.run([sys.executable, "-m", "hindrax_bringup.gateway.node", "--ros-args", "--params-file",
                        str(CONFIG), "-p", setting], capture_output=True, text=True, env=child_env(), timeout=60)
    assert r.returncode == 1
    errors = [x for x in r.stderr.splitlines() if x.startswith("invalid configuration")]
    assert len(errors) == 1 and line in errors[0], r.stderr


def _run_goal_against(frames):
    """Run the gateway's goal relay on a stand-in gateway whose internal side answers a goal with ``frames``
    ([(head, message or None)], ids filled in); returns (result, what the topside handle saw)."""
    import itertools
    import threading
    from types import SimpleNamespace

    from rclpy.serialization import serialize_message

    from hindrax_bringup.gateway.node import Gateway
    from hindrax_msgs.action import RunIdentification

    sent: list = []  # the kinds of the frames the relay sent to the internal side
    gw = SimpleNamespace(verifier=SimpleNamespace(check_message=lambda *_: ""),
                         bounds=SimpleNamespace(goal_problem=lambda _g: ""), _ids=itertools.count(1), _goals={},
                         settings=SimpleNamespace(call_timeout_s=0.3), _action_type=RunIdentification,
                         campaign=SimpleNamespace(context=SimpleNamespace(ok=lambda: True)), _refuse=lambda w, *_: w)

    def send(head, payload=b""):
        sent.append(head["k"])
        if head["k"] == "goal":
            delay_s = 0.0  # ("wait", s): the frames after it come s later
            for frame, message in frames:
                if frame == "wait":
                    delay_s += message
                    continue
                item = ({**frame, "id": head["id"]}, b"" if message is None else serialize_message(message))
                threading.Timer(delay_s, gw._goals[head["id"]].put, (item,)).start()

    gw.channel = SimpleNamespace(send=send)
    gw._campaign_running = threading.Lock()  # one campaign at a time: held while the relay runs
    gw._closing = threading.Event()  # the gateway is not shutting down
    gw._relay_goal = lambda goal_handle, failed: Gateway._relay_goal(gw, goal_handle, failed)
    seen = []
    handle = SimpleNamespace(request=RunIdentification.Goal(dofs=["surge"]), is_cancel_requested=False,
                             publish_feedback=seen.append, succeed=lambda: seen.append("succeeded"),
                             abort=lambda: seen.append("aborted"), canceled=lambda: seen.append("canceled"))
    out = Gateway._run_goal(gw, handle)
    return out, [type(x).__name__ if not isinstance(x, str) else x for x in seen], sent


def test_feedback_that_overtakes_the_acceptance_is_relayed_and_the_goal_runs_on():
    """On the internal side a running goal's first feedback can reach the gateway before its acceptance (the action
    client's feedback callback runs before the send-goal future's): the topside goal is relayed that feedback and
    ends with the internal result, never read as refused."""
    from action_msgs.msg import GoalStatus

    from hindrax_msgs.action import RunIdentification

    out, seen, _ = _run_goal_against([
        ({"k": "feedback"}, RunIdentification.Feedback(dof="surge", level_index=0, level_count=1)),
        ({"k": "accepted", "ok": True, "why": ""}, None),
        ({"k": "result", "status": GoalStatus.STATUS_SUCCEEDED}, RunIdentification.Result(success=True,
                                                                                          message="done"))])
    assert out.success and out.message == "done"
    assert seen == ["RunIdentification_Feedback", "succeeded"]


@pytest.mark.parametrize("frames, message", [
    ([({"k": "accepted", "ok": False, "why": "not armed"}, None)], "run_identification: not armed"),
    ([({"k": "gone"}, None)], "run_identification: the gateway's internal side is gone"),
    ([], "run_identification: no answer from the identification node within 0.3 s"),
])
def test_a_goal_that_is_not_accepted_fails_on_the_topside_with_its_cause(frames, message):
    """A refusal, the internal side ending, or no answer before the call timeout each abort the topside goal with
    their own cause (the internal side ending is not reported as a refusal)."""
    out, seen, sent = _run_goal_against(frames)
    assert not out.success and out.message == message
    assert seen == ["aborted"]
    # given up unanswered: the goal is cancelled inside, so a late acceptance does not run unseen
    assert sent == (["goal", "cancel"] if "no answer" in message else ["goal"])


def test_feedback_without_an_acceptance_is_one_and_the_goal_runs_to_its_result():
    """A goal whose acceptance never reaches the gateway (the send-goal response lost inside) but whose feedback
    does: it runs; the topside goal takes the internal result, not "no answer" after call_timeout_s (0.3 s here).
    Seen in a fresh clone's README walk: "no answer from the identification node within 4 s" while the campaign's
    positioning feedback was relayed."""
    from action_msgs.msg import GoalStatus

    from hindrax_msgs.action import RunIdentification

    out, seen, sent = _run_goal_against([
        ({"k": "feedback"}, RunIdentification.Feedback(dof="heave", level_index=0, level_count=1)),
        ("wait", 0.6),
        ({"k": "result", "status": GoalStatus.STATUS_SUCCEEDED}, RunIdentification.Result(success=True,
                                                                                          message="done"))])
    assert out.success and out.message == "done", out.message
    assert seen == ["RunIdentification_Feedback", "succeeded"] and sent == ["goal"]


def test_the_internal_side_takes_a_goal_whose_response_is_lost_as_accepted_by_its_feedback():
    """The internal side against a real action server whose send-goal response never reaches the client (Fast DDS
    drops it before the server matched the client: hindrax_common/node_support/action_goal.py): the first feedback
    makes it accepted, the result is fetched and relayed; a cancel that came before any answer is sent once the
    goal is known accepted."""
    import time
    from types import SimpleNamespace

    from rclpy.action import ActionServer, CancelResponse
    from rclpy.executors import MultiThreadedExecutor
    from rclpy.task import Future

    from hindrax_bringup.gateway.interface import relays
    from hindrax_bringup.gateway.internal import InternalSide
    from hindrax_common.testing import ros_context, wait_until
    from hindrax_msgs.action import RunIdentification
    from rclpy.serialization import serialize_message

    with ros_context() as ctx:
        import rclpy

        node = rclpy.create_node("gateway", namespace="/alpha", context=ctx)
        frames: list = []
        side = InternalSide(node, SimpleNamespace(send=lambda head, payload=b"": frames.append(head)))
        original = side.action.send_goal_async
        side.action.send_goal_async = lambda *a, **k: (original(*a, **k), Future())[1]  # the response is lost

        def campaign(goal_handle):
            while not goal_handle.is_cancel_requested and time.monotonic() < deadline:
                goal_handle.publish_feedback(RunIdentification.Feedback(dof="surge"))
                time.sleep(0.05)
            if goal_handle.is_cancel_requested:
                goal_handle.canceled()
                return RunIdentification.Result(success=False, message="cancelled")
            goal_handle.succeed()
            return RunIdentification.Result(success=True, message="done")

        (action,) = relays("action")
        server = ActionServer(node, RunIdentification, action.internal, campaign,
                              cancel_callback=lambda _g: CancelResponse.ACCEPT)
        executor = MultiThreadedExecutor(num_threads=3, context=ctx)
        executor.add_node(node)
        spin = lambda: executor.spin_once(timeout_sec=0.05)  # noqa: E731
        wait_until(side.action.server_is_ready, 30, spin, "the action server")
        goal = serialize_message(RunIdentification.Goal(dofs=["surge"]))
        kinds = lambda i: [f["k"] for f in frames if f.get("id") == i]  # noqa: E731
        deadline = time.monotonic() + 1.0
        side._on_goal({"k": "goal", "id": 1}, goal)
        wait_until(lambda: "result" in kinds(1), 30, spin, "goal 1's result")
        assert kinds(1)[0] == "accepted" and [f for f in frames if f.get("k") == "accepted"][0]["ok"]
        assert [f["status"] for f in frames if f.get("k") == "result"] == [4]  # STATUS_SUCCEEDED
        # cancelled by the topside before it was known accepted: cancelled as soon as it is
        deadline = time.monotonic() + 30.0
        side._on_cancel({"k": "cancel", "id": 2}, b"")
        side._on_goal({"k": "goal", "id": 2}, goal)
        wait_until(lambda: "result" in kinds(2), 30, spin, "goal 2's result")
        assert [f["status"] for f in frames if f.get("k") == "result" and f["id"] == 2] == [5]  # CANCELED
        server.destroy()
        executor.shutdown()
        node.destroy_node()


def test_a_service_answering_after_2_5_s_is_relayed_with_the_default_patience():
    """An internal service slow under load (controller/enable: "no answer within 2 s" in a loaded suite) is relayed
    with the default ``call_timeout_s`` (4 s: below the 5 s that ``hindrax arm`` and ``hindrax ident status`` wait,
    so a silent service is still reported by the gateway, not by the command giving up)."""
    import itertools
    import threading
    from types import SimpleNamespace

    from rclpy.serialization import serialize_message
    from std_srvs.srv import SetBool

    from hindrax_bringup.gateway.internal import DEFAULT_CALL_TIMEOUT_S
    from hindrax_bringup.gateway.node import Gateway

    def answer_late(head, payload=b""):
        reply = ({"id": head["id"], "ok": True}, serialize_message(SetBool.Response(success=True, message="released")))
        threading.Timer(2.5, lambda: gw._pending[head["id"]].set_result(reply)).start()
        return True

    gw = SimpleNamespace(_ids=itertools.count(1), _pending={}, channel=SimpleNamespace(send=answer_late),
                         settings=SimpleNamespace(call_timeout_s=DEFAULT_CALL_TIMEOUT_S))
    response, why = Gateway.call(gw, "controller/enable", SetBool.Request(data=False), SetBool)
    assert why == "" and response.message == "released"


def test_a_second_answer_to_one_call_is_dropped_and_the_reader_reads_on():
    """The internal side answering one call twice (a fault on the channel) leaves the first answer
    with the caller and the channel's reader thread reading the frames after it."""
    import queue
    from concurrent.futures import Future
    from types import SimpleNamespace

    from hindrax_bringup.gateway.node import Gateway

    answer = {"k": "answer", "id": 1, "ok": True}
    result = ({"k": "result", "id": 2}, b"goal")
    frames = iter([(answer, b"first"), (answer, b"again"), result, None])
    pending, goal = Future(), queue.Queue()
    gw = SimpleNamespace(channel=SimpleNamespace(recv=lambda: next(frames)), _pending={1: pending},
                         _goals={2: goal}, _out={}, relayed={"messages": 0}, executors=[])
    Gateway._read_channel(gw)
    assert pending.result(timeout=0) == (answer, b"first")
    assert goal.get_nowait() == result
    assert goal.get_nowait() == ({"k": "gone"}, b"")
