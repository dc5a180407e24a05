"""The one-process graph's executor (hindrax_sim.graph.ordered_executor): the lean wait yields what
rclpy's own wait yields, in the same order, the executor visits its nodes in the order they were
added, and plain callbacks run through its own handler."""
from __future__ import annotations

import rclpy
from rclpy.executors import Executor, TimeoutException
from std_msgs.msg import String
from std_srvs.srv import Trigger

from hindrax_common.testing import ros_context, wait_until
from hindrax_sim.graph.ordered_executor import LeanWaitExecutor


def _drain(gen) -> list:
    """Entities a wait generator yields (handlers not run) until it times out."""
    out = []
    try:
        for _handler, entity, node in gen:
            out.append((node.get_name(), type(entity).__name__, id(entity)))
    except TimeoutException:
        pass
    return out


def _forget(executor) -> None:
    """Undo what yielding did (handlers never run): the entities wait again, no task is pending."""
    for task, entity, _node in executor._tasks:
        entity._executor_event = False
        task.cancel()  # its coroutine closed, never run
    executor._tasks.clear()


def test_lean_wait_yields_rclpys_callbacks_in_rclpys_order():
    with ros_context() as ctx:
        ex = LeanWaitExecutor(context=ctx)
        names = ["zeta", "alpha", "mid"]  # added in this order, not alphabetical
        nodes = [rclpy.create_node(n, context=ctx) for n in names]
        for node in nodes:
            ex.add_node(node)
        got: list = []
        pubs = []
        timers = []
        for node in nodes:
            timers.append(node.create_timer(0.001, lambda: None))
            node.create_subscription(String, "chatter", got.append, 10)
            node.create_subscription(String, f"{node.get_name()}/own", got.append, 10)
            node.create_service(Trigger, f"{node.get_name()}/go", lambda _q, r: r)
            pubs.append(node.create_publisher(String, "chatter", 10))
        clients = [nodes[0].create_client(Trigger, f"{n}/go") for n in names]
        wait_until(lambda: (all(c.service_is_ready() for c in clients)
                            and pubs[0].get_subscription_count() == 3),
                   20, lambda: None, "discovery")
        for c in clients[::-1]:
            c.call_async(Trigger.Request())
        pubs[1].publish(String(data="x"))
        guard = nodes[2].create_guard_condition(lambda: None)
        guard.trigger()
        # every timer due, every service and subscription with work: both waits see the same ready
        # entities
        wait_until(lambda: all(t.time_until_next_call() <= 0 for t in timers), 5, None,
                   "timers due")
        lean = _drain(ex._wait_for_ready_callbacks(0.0))
        _forget(ex)
        plain = _drain(Executor._wait_for_ready_callbacks(ex, 0.0))
        _forget(ex)
        assert lean == plain
        kinds = [k for _n, k, _i in lean]
        assert {"Timer", "Subscription", "Service", "GuardCondition"} <= set(kinds)
        # nodes in the order added
        assert [n for n in dict.fromkeys(n for n, _k, _i in lean)] == names
        assert ex.get_nodes() == nodes
        ex.remove_node(nodes[1])
        assert ex.get_nodes() == [nodes[0], nodes[2]]
        ex.shutdown()


def test_a_handle_no_longer_valid_leaves_none_held():
    """The lean wait enters the snapshot's handles in one pass: when one of them was destroyed
    meanwhile, the ones entered before it are released again (last first) and the wait goes the
    entity-by-entity way."""
    from rclpy.exceptions import InvalidHandle

    from hindrax_sim.graph.ordered_executor import _enter_each

    log: list = []

    class Handle:
        def __init__(self, name: str, valid: bool = True) -> None:
            self.name, self.valid = name, valid

        def __enter__(self):
            if not self.valid:
                raise InvalidHandle("destroyed")
            log.append(("enter", self.name))

        def __exit__(self, *_exc) -> None:
            log.append(("exit", self.name))

    good = [Handle("a"), Handle("b"), Handle("c")]
    held = _enter_each(good)
    assert held == good and held is not good
    assert log == [("enter", "a"), ("enter", "b"), ("enter", "c")]
    log.clear()
    assert _enter_each([Handle("a"), Handle("b"), Handle("x", valid=False), Handle("d")]) is None
    assert log == [("enter", "a"), ("enter", "b"), ("exit", "b"), ("exit", "a")]


def test_plain_callbacks_run_at_once_and_their_errors_reach_the_spinner():
    """A ready timer or subscription with a plain callback runs through the executor's own handler
    (message delivered, the exception raised from ``spin_once``); a coroutine callback still runs
    through rclpy's Task."""
    import pytest

    from hindrax_sim.graph.ordered_executor import _Call

    with ros_context() as ctx:
        ex = LeanWaitExecutor(context=ctx)
        node = rclpy.create_node("calls", context=ctx)
        ex.add_node(node)
        got: list = []
        node.create_subscription(String, "plain", lambda m: got.append(m.data), 10)

        async def later(m):
            got.append("async " + m.data)
        node.create_subscription(String, "coro", later, 10)
        pub, pub_coro = (node.create_publisher(String, t, 10) for t in ("plain", "coro"))
        wait_until(lambda: (pub.get_subscription_count() == 1
                            and pub_coro.get_subscription_count() == 1),
                   20, lambda: None, "discovery")
        pub.publish(String(data="a"))
        handler, _entity, _node = ex.wait_for_ready_callbacks(5.0)
        assert isinstance(handler, _Call) and got == []
        handler()
        assert handler.done() and handler.exception() is None and got == ["a"]
        pub_coro.publish(String(data="b"))
        handler, _entity, _node = ex.wait_for_ready_callbacks(5.0)
        assert not isinstance(handler, _Call)
        handler()
        assert got == ["a", "async b"]

        def boom():
            raise ValueError("tick failed")
        timer = node.create_timer(0.001, boom)
        wait_until(lambda: timer.time_until_next_call() <= 0, 5, None, "timer due")
        with pytest.raises(ValueError, match="tick failed"):
            ex.spin_once(5.0)
        ex.shutdown()


def test_snapshot_handles_held_from_one_wait_to_the_next(monkeypatch):
    """The lean wait marks its snapshot's handles in use once, not at every wait; an entity
    destroyed meanwhile is released at the next wait (a new snapshot), every handle at shutdown."""
    import hindrax_sim.graph.ordered_executor as oe

    entered: list = []
    enter = oe._ENTER
    monkeypatch.setattr(oe, "_ENTER", lambda h: (entered.append(h), enter(h)))
    with ros_context() as ctx:
        ex = LeanWaitExecutor(context=ctx)
        node = rclpy.create_node("held", context=ctx, start_parameter_services=False)
        ex.add_node(node)
        ran: list = []
        sub = node.create_subscription(String, "held_topic", ran.append, 10)
        node.create_timer(0.001, lambda: ran.append("tick"))
        ex.spin_once(timeout_sec=1.0)
        first = len(entered)
        assert sub.handle in entered and sub.handle in ex._held
        for _ in range(5):
            ex.spin_once(timeout_sec=1.0)
        assert len(entered) == first and ran.count("tick") >= 5  # waited, entered nothing more
        node.destroy_subscription(sub)
        ex.spin_once(timeout_sec=1.0)
        assert len(entered) > first and sub.handle not in ex._held
        assert ex.shutdown() and ex._held == []
        node.destroy_node()
