"""The one-process graph's executor: rclpy's ``SingleThreadedExecutor`` visiting its nodes in the order they were added,
with a leaner construction of its wait set.

Order: rclpy keeps an executor's nodes in a set, so the order in which the callbacks that are ready at the same
instant run (e.g. the allocation's wrench subscription and the ESC node's output timer) follows the nodes' memory
addresses and changes from one run to the next; with a fixed order a stepped simulation is reproducible.

Wait set: rclpy 7.1 (Jazzy) builds a new wait set for every wait, entering each entity's handle through an
``ExitStack``, asking every entity's callback group (a weak reference and a lock each), adding up the waitables'
``NumberOfEntities`` one object at a time and looking every entity of every node up in the ready lists; the virtual
pool's graph has about 370 entities (90 parameter services, 120 QoS event handlers) and waits once per /clock tick:
1.1 ms of CPU a wait. :meth:`LeanWaitExecutor._wait_for_ready_callbacks` does the same wait and yields the same
callbacks in the same order (tasks in progress; ready waitables node by node; then per node its timers,
subscriptions, guard conditions, clients and services in creation order) in 0.7 ms: handles entered directly, rclpy's
two callback groups answered from their state, the waitables' entity counts summed as integers once known, the ready
entities found by their handle pointers.
"""
from __future__ import annotations

from typing import Any, Callable

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import (ConditionReachedException, ExternalShutdownException, ShutdownException,
                             SingleThreadedExecutor, TimeoutException, TimeoutObject, timeout_sec_to_nsec)
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.timer import Timer
from rclpy.exceptions import InvalidHandle

__all__ = ["LeanWaitExecutor", "ordered_executor"]

#: NumberOfEntities fields in the order _rclpy.WaitSet takes them (after subscriptions: guards, timers, clients,
#: services, events)
_COUNT_FIELDS = ("num_subscriptions", "num_guard_conditions", "num_timers", "num_clients", "num_services",
                 "num_events")


def _free(entity) -> bool:
    """``Executor.can_execute(entity)``: no handler pending and its callback group lets it run. rclpy's two groups
    answered from their state (their ``can_execute`` also asserts the entity's membership, under a lock, at every
    wait: a tenth of the wait), any other group asked."""
    if entity._executor_event:
        return False
    group = entity.callback_group
    kind = type(group)
    if kind is MutuallyExclusiveCallbackGroup:
        return group._active_entity is None
    return kind is ReentrantCallbackGroup or group.can_execute(entity)


def _counts(waitable) -> tuple:
    """A waitable's entity counts (fixed for its life: the rcl entities it wraps), asked once."""
    c = waitable.__dict__.get("_lean_wait_counts")
    if c is None:
        n = waitable.get_num_entities()
        c = waitable.__dict__["_lean_wait_counts"] = tuple(getattr(n, f) for f in _COUNT_FIELDS)
    return c


class LeanWaitExecutor(SingleThreadedExecutor):
    """A ``SingleThreadedExecutor`` whose nodes run in the order they were added and whose wait is
    :meth:`_wait_for_ready_callbacks` (module docstring). ``kwargs`` go to the executor (``context``)."""

    def __init__(self, **kw: Any) -> None:
        self._order: list = []
        super().__init__(**kw)

    def add_node(self, node: Any) -> bool:
        added = super().add_node(node)
        if node not in self._order:
            self._order.append(node)
        return added

    def remove_node(self, node: Any) -> None:
        super().remove_node(node)
        if node in self._order:
            self._order.remove(node)

    def get_nodes(self) -> list:
        present = set(super().get_nodes())
        return [n for n in self._order if n in present]

    def _wait_for_ready_callbacks(self, timeout_sec=None, nodes=None, condition: Callable[[], bool] = lambda: False):
        """rclpy's ``Executor._wait_for_ready_callbacks`` (same arguments, exceptions, callbacks and order), with the
        wait set built as the module docstring says."""
        timeout_timer = None
        timeout_nsec = timeout_sec_to_nsec(
            timeout_sec.timeout if isinstance(timeout_sec, TimeoutObject) else timeout_sec)
        if timeout_nsec > 0:
            timeout_timer = Timer(None, None, timeout_nsec, self._clock, context=self._context)

        yielded_work = False
        while not yielded_work and not self._is_shutdown and not condition():
            nodes_to_use = self.get_nodes() if nodes is None else nodes

            # tasks in progress first
            with self._tasks_lock:
                tasks = list(self._tasks)
            if tasks:
                for task, entity, node in reversed(tasks):
                    if not task.executing() and not task.done() and (node is None or node in nodes_to_use):
                        yielded_work = True
                        yield task, entity, node
                with self._tasks_lock:
                    self._tasks = [t for t in self._tasks if not t[0].done() and not t[0].cancelled()]

            can = _free
            subs, timers, clients, services, guards, waitables = [], [], [], [], [], []
            for node in nodes_to_use:
                subs.extend(filter(can, node.subscriptions))
                timers.extend(filter(can, node.timers))
                clients.extend(filter(can, node.clients))
                services.extend(filter(can, node.services))
                for gc in filter(can, node.guards):
                    if gc._executor_triggered:  # retrigger a guard condition that was triggered but not handled
                        gc.trigger()
                    guards.append(gc)
                waitables.extend(filter(can, node.waitables))
            if timeout_timer is not None:
                timers.append(timeout_timer)
            guards.append(self._guard)
            guards.append(self._sigint_gc)

            entered: list = []  # handles (and waitables) marked in use while waiting, exited in reverse order
            try:
                handles = []
                for group in (subs, clients, services, timers, guards):
                    kept = []
                    for entity in group:
                        h = entity.handle
                        try:
                            h.__enter__()
                        except InvalidHandle:
                            continue
                        entered.append(h)
                        kept.append(h)
                    handles.append(kept)
                sub_h, cli_h, srv_h, tmr_h, gc_h = handles
                counts = [len(sub_h), len(gc_h), len(tmr_h), len(cli_h), len(srv_h), 0]
                in_set = []
                for wt in waitables:
                    try:
                        wt.__enter__()
                    except InvalidHandle:
                        continue
                    entered.append(wt)
                    in_set.append(wt)
                    counts = [a + b for a, b in zip(counts, _counts(wt))]
                self._context.handle.__enter__()
                entered.append(self._context.handle)

                wait_set = _rclpy.WaitSet(*counts, self._context.handle)
                wait_set.clear_entities()
                for h in sub_h:
                    wait_set.add_subscription(h)
                for h in cli_h:
                    wait_set.add_client(h)
                for h in srv_h:
                    wait_set.add_service(h)
                for h in tmr_h:
                    wait_set.add_timer(h)
                for h in gc_h:
                    wait_set.add_guard_condition(h)
                for wt in in_set:
                    wt.add_to_wait_set(wait_set)

                wait_set.wait(timeout_nsec)
                if self._is_shutdown:
                    raise ShutdownException()
                if not self._context.ok():
                    raise ExternalShutdownException()

                subs_ready = set(wait_set.get_ready_entities('subscription'))
                guards_ready = set(wait_set.get_ready_entities('guard_condition'))
                timers_ready = set(wait_set.get_ready_entities('timer'))
                clients_ready = set(wait_set.get_ready_entities('client'))
                services_ready = set(wait_set.get_ready_entities('service'))

                # guards are auto-taken: mark them triggered before yielding
                for gc in guards:
                    if gc.handle.pointer in guards_ready:
                        gc._executor_triggered = True

                # ready waitables, checked before the wait set is destroyed
                waiting = set(map(id, in_set))
                for node in nodes_to_use:
                    for wt in node.waitables:
                        if id(wt) in waiting and wt.is_ready(wait_set) and wt.callback_group.can_execute(wt):
                            yielded_work = True
                            yield self._make_handler(wt, node, self._take_waitable), wt, node
            finally:
                for h in reversed(entered):
                    h.__exit__(None, None, None)

            # ready entities one node at a time, in rclpy's order
            for node in nodes_to_use:
                if timers_ready:
                    for tmr in node.timers:
                        if tmr.handle.pointer in timers_ready and tmr.handle.is_timer_ready() and \
                                tmr.callback_group.can_execute(tmr):
                            yielded_work = True
                            yield self._make_handler(tmr, node, self._take_timer), tmr, node
                if subs_ready:
                    for sub in node.subscriptions:
                        if sub.handle.pointer in subs_ready and sub.callback_group.can_execute(sub):
                            yielded_work = True
                            yield self._make_handler(sub, node, self._take_subscription), sub, node
                for gc in node.guards:
                    if gc._executor_triggered and gc.callback_group.can_execute(gc):
                        yielded_work = True
                        yield self._make_handler(gc, node, self._take_guard_condition), gc, node
                if clients_ready:
                    for client in node.clients:
                        if client.handle.pointer in clients_ready and client.callback_group.can_execute(client):
                            yielded_work = True
                            yield self._make_handler(client, node, self._take_client), client, node
                if services_ready:
                    for srv in node.services:
                        if srv.handle.pointer in services_ready and srv.callback_group.can_execute(srv):
                            yielded_work = True
                            yield self._make_handler(srv, node, self._take_service), srv, node

            if timeout_nsec == 0 or (timeout_timer is not None and timeout_timer.handle.pointer in timers_ready):
                raise TimeoutException()
        if self._is_shutdown:
            raise ShutdownException()
        if condition():
            raise ConditionReachedException()


def ordered_executor(**kwargs: Any) -> LeanWaitExecutor:
    """The executor of the one-process graph (:class:`LeanWaitExecutor`; module docstring). ``kwargs`` go to the
    executor (``context``)."""
    return LeanWaitExecutor(**kwargs)
