"""The one-process graph's executor: rclpy's ``SingleThreadedExecutor`` visiting its nodes in the
order they were added, with a leaner construction of its wait set and of its callbacks' handlers.

Order: rclpy keeps an executor's nodes in a set, so the order in which the callbacks that are ready at the same instant
run (e.g. the allocation's wrench subscription and the ESC node's output timer) follows the nodes' memory addresses and
changes from one run to the next; with a fixed order a stepped simulation is reproducible.

Wait set: rclpy 7.1 (Jazzy) builds a new wait set for every wait, entering each entity's handle through an
``ExitStack``, asking every entity's callback group (a weak reference and a lock each), adding up the waitables'
``NumberOfEntities`` one object at a time and looking every entity of every node up in the ready lists; the virtual
pool's graph waits once per /clock tick, on about 120 entities
(:class:`~hindrax_common.node_support.vehicle_node.VehicleNode`s: no parameter services, few QoS event handlers).
:meth:`LeanWaitExecutor._wait_for_ready_callbacks` does the same wait and yields the same callbacks in the same order
(tasks in progress; ready waitables node by node; then per node its timers, subscriptions, guard conditions, clients and
services in creation order) from a snapshot of the nodes' entities (:class:`_Snapshot`: handles, entity counts, each
entity's rank in that order by its handle pointer), taken again whenever an entity or a node comes or goes (rclpy wakes
the executor then: :meth:`LeanWaitExecutor.wake`). With no task in progress every entity is free to run (a callback
group is busy, or an entity's handler pending, only inside a task), so the snapshot's lists go into the wait set as they
are; otherwise each entity is asked as rclpy asks it. The snapshot's handles are marked in use (rclpy enters each at
every wait) once, when it is taken, and released in the executor's thread when the next one is taken, or at
``shutdown``: an entity destroyed meanwhile (out of the snapshot from its wake on) is freed then. QoS event handlers
(most waitables) enter their event handle into the wait set directly, without their Python wrappers. A wait over a
subset of the nodes is rclpy's.

Handlers: a ready timer or subscription whose callback is a plain function gets a :class:`_Call`;
the other entities get rclpy's."""
from __future__ import annotations

import inspect
import weakref
from collections import deque
from operator import methodcaller
from typing import Any, Callable

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.event_handler import EventHandler
from rclpy.executors import (ConditionReachedException, ExternalShutdownException,
                             ShutdownException, SingleThreadedExecutor, TimeoutException,
                             TimeoutObject, timeout_sec_to_nsec)
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.subscription import Subscription
from rclpy.timer import Timer
from rclpy.exceptions import InvalidHandle

__all__ = ["LeanWaitExecutor"]

#: NumberOfEntities fields in the order _rclpy.WaitSet takes them (after subscriptions: guards,
#: timers, clients, services, events)
_COUNT_FIELDS = ("num_subscriptions", "num_guard_conditions", "num_timers", "num_clients", "num_services", "num_events")
#: entity kinds in rclpy's per-node order of ready callbacks
_TIMER, _SUB, _GUARD, _CLIENT, _SERVICE = range(5)
#: a handle's ``__enter__`` / ``__exit__`` as C-level calls (the wait enters and leaves every handle)
_ENTER, _EXIT = methodcaller("__enter__"), methodcaller("__exit__", None, None, None)
_MESSAGE_ONLY = Subscription.CallbackType.MessageOnly


def _free(entity) -> bool:
    """``Executor.can_execute(entity)``: no handler pending and its callback group lets it run.
    rclpy's two groups answered from their state (their ``can_execute`` also asserts the entity's
    membership, under a lock, at every wait: a tenth of the wait), any other group asked."""
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


class _Snapshot:
    """The entities of ``nodes`` (in that order) as the wait needs them: per kind the entities in
    rclpy's order, the waitables with their node, ``rank``: handle pointer -> (rank in rclpy's order
    of ready callbacks, kind, entity, node)."""

    def __init__(self, nodes: list) -> None:
        self.nodes = nodes
        self.subs, self.timers, self.clients, self.services, self.guards = [], [], [], [], []
        self.waitables: list = []  # (waitable, node)
        self.held = False  # its handles marked in use (LeanWaitExecutor)
        self.rank: dict = {}
        self.guard_rank: list = []  # (rank, kind, guard, node)
        counts = [0] * 6
        r = 0
        for node in nodes:
            for kind, entities, out in ((_TIMER, node.timers, self.timers),
                                        (_SUB, node.subscriptions, self.subs),
                                        (_GUARD, node.guards, self.guards),
                                        (_CLIENT, node.clients, self.clients),
                                        (_SERVICE, node.services, self.services)):
                for e in entities:
                    out.append(e)
                    entry = (r, kind, e, node)
                    if kind == _GUARD:
                        self.guard_rank.append(entry)
                    else:
                        self.rank[e.handle.pointer] = entry
                    r += 1
            for wt in node.waitables:
                self.waitables.append((wt, node))
                counts = [a + b for a, b in zip(counts, _counts(wt))]
        self.waitable_counts = counts
        # with every entity free (no task in progress) the wait takes these as they are: the handles of the
        # subscriptions, clients, services and timers, then the QoS event handlers' event handles (module docstring)
        self.sub_h, self.cli_h, self.srv_h, self.tmr_h = ([e.handle for e in group] for group in (
            self.subs, self.clients, self.services, self.timers))
        self.events = [(wt, node, wt._EventHandler__event) for wt, node in self.waitables
                       if isinstance(wt, EventHandler)]
        self.others = [(wt, node) for wt, node in self.waitables if not isinstance(wt, EventHandler)]
        self.handles = (self.sub_h + self.cli_h + self.srv_h + self.tmr_h + [h for *_w, h in self.events])


def _enter_each(handles: list) -> list | None:
    """Mark every handle in use (``__enter__``) in order and return a new list of them, or None
    (none left held) when one is no longer valid."""
    rest = iter(handles)
    try:
        deque(map(_ENTER, rest), 0)
    except InvalidHandle:
        _exit_each(handles[:len(handles) - len(list(rest)) - 1])
        return None
    return list(handles)


def _exit_each(handles: list) -> None:
    """Release handles entered by :func:`_enter_each` (or one by one), last first."""
    deque(map(_EXIT, reversed(handles)), 0)


def _release(held: list) -> None:
    """Release the handles a snapshot holds (:func:`_exit_each`) and forget them."""
    _exit_each(held)
    held.clear()


class LeanWaitExecutor(SingleThreadedExecutor):
    """A ``SingleThreadedExecutor`` whose nodes run in the order they were added and whose wait is
    :meth:`_wait_for_ready_callbacks` (module docstring). ``kwargs`` go to the executor (``context``)."""

    def __init__(self, **kw: Any) -> None:
        self._order: list = []
        self._snapshot: _Snapshot | None = None
        self._held: list = []  # the snapshot's handles while they are marked in use
        super().__init__(**kw)
        weakref.finalize(self, _release, self._held)

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        """rclpy's shutdown; then the snapshot's handles are released (its entities may go)."""
        done = super().shutdown(timeout_sec)
        if done:
            self._snapshot = None
            _release(self._held)
        return done

    def wake(self) -> None:
        """rclpy's wake (an entity was created or destroyed, a task finished); the next wait takes a new snapshot."""
        self._snapshot = None
        super().wake()

    def add_node(self, node: Any) -> bool:
        added = super().add_node(node)
        if node not in self._order:
            self._order.append(node)
        self._snapshot = None
        return added

    def remove_node(self, node: Any) -> None:
        super().remove_node(node)
        if node in self._order:
            self._order.remove(node)
        self._snapshot = None

    def get_nodes(self) -> list:
        present = set(super().get_nodes())
        return [n for n in self._order if n in present]

    def _take(self, kind: int) -> Callable:
        return (self._take_timer, self._take_subscription, self._take_guard_condition,
                self._take_client, self._take_service)[kind]

    def _wait_for_ready_callbacks(self, timeout_sec=None, nodes=None, condition: Callable[[], bool] = lambda: False):
        """rclpy's ``Executor._wait_for_ready_callbacks`` (same arguments, exceptions, callbacks and
        order), with the wait set built as the module docstring says."""
        if nodes is not None:
            yield from super()._wait_for_ready_callbacks(timeout_sec, nodes, condition)
            return
        timeout_timer = None
        timeout_nsec = timeout_sec_to_nsec(
            timeout_sec.timeout if isinstance(timeout_sec, TimeoutObject) else timeout_sec)
        if timeout_nsec > 0:
            timeout_timer = Timer(None, None, timeout_nsec, self._clock, context=self._context)

        yielded_work = False
        while not yielded_work and not self._is_shutdown and not condition():
            snap = self._snapshot
            if snap is None:
                _release(self._held)
                snap = _Snapshot(self.get_nodes())
                self._held.extend(_enter_each(snap.handles) or ())  # none if one is not valid
                snap.held = bool(self._held) or not snap.handles
                self._snapshot = snap
            nodes_to_use = snap.nodes

            # tasks in progress first
            with self._tasks_lock:
                tasks = list(self._tasks)
            if tasks:
                for task, entity, node in reversed(tasks):
                    if (not task.executing() and not task.done() and (node is None or node in nodes_to_use)):
                        yielded_work = True
                        yield task, entity, node
                with self._tasks_lock:
                    self._tasks = [t for t in self._tasks if not t[0].done() and not t[0].cancelled()]
                    busy = bool(self._tasks)
            else:
                busy = False

            # with no task in progress every entity is free (module docstring)
            pick = (lambda xs: list(filter(_free, xs))) if busy else list
            subs, timers = pick(snap.subs), pick(snap.timers)
            clients, services = pick(snap.clients), pick(snap.services)
            guards = []
            for gc in pick(snap.guards):
                if gc._executor_triggered:  # retrigger one that was triggered but not handled
                    gc.trigger()
                guards.append(gc)
            waitables = [(wt, node) for wt, node in snap.waitables if not busy or _free(wt)]
            if timeout_timer is not None:
                timers.append(timeout_timer)
            guards.append(self._guard)
            guards.append(self._sigint_gc)

            # handles marked in use while waiting, exited in reverse order: with every entity free
            # the snapshot's (held since it was taken), else each free entity's
            fast = not busy and snap.held
            entered: list = []
            try:
                handles = []
                for group in ((timers[len(snap.timers):], guards) if fast else
                              (subs, clients, services, timers, guards)):
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
                if fast:
                    extra_tmr_h, gc_h = handles
                    sub_h, cli_h, srv_h = snap.sub_h, snap.cli_h, snap.srv_h
                    tmr_h = snap.tmr_h + extra_tmr_h
                    events, others, waitables = snap.events, [], snap.others
                else:
                    sub_h, cli_h, srv_h, tmr_h, gc_h = handles
                    events, others = [], []  # (waitable, node, event handle) / (waitable, node)
                for wt, node in waitables:
                    h = wt._EventHandler__event if isinstance(wt, EventHandler) else wt
                    try:
                        h.__enter__()
                    except InvalidHandle:
                        continue
                    entered.append(h)
                    if h is wt:
                        others.append((wt, node))
                    else:
                        events.append((wt, node, h))
                counts = [len(sub_h), len(gc_h), len(tmr_h), len(cli_h), len(srv_h), 0]
                if busy or len(events) + len(others) != len(snap.waitables):
                    for wt, *_ in events + others:
                        counts = [a + b for a, b in zip(counts, _counts(wt))]
                else:
                    counts = [a + b for a, b in zip(counts, snap.waitable_counts)]
                self._context.handle.__enter__()
                entered.append(self._context.handle)

                wait_set = _rclpy.WaitSet(*counts, self._context.handle)
                wait_set.clear_entities()
                for add, hs in ((wait_set.add_subscription, sub_h), (wait_set.add_client, cli_h),
                                (wait_set.add_service, srv_h), (wait_set.add_timer, tmr_h),
                                (wait_set.add_guard_condition, gc_h)):
                    deque(map(add, hs), 0)
                add_event = wait_set.add_event
                for wt, _node, h in events:
                    wt._event_index = add_event(h)
                for wt, _node in others:
                    wt.add_to_wait_set(wait_set)

                wait_set.wait(timeout_nsec)
                if self._is_shutdown:
                    raise ShutdownException()
                if not self._context.ok():
                    raise ExternalShutdownException()

                subs_ready = wait_set.get_ready_entities('subscription')
                guards_ready = set(wait_set.get_ready_entities('guard_condition'))
                timers_ready = wait_set.get_ready_entities('timer')
                clients_ready = wait_set.get_ready_entities('client')
                services_ready = wait_set.get_ready_entities('service')

                # guards are auto-taken: mark them triggered before yielding
                for gc in guards:
                    if gc.handle.pointer in guards_ready:
                        gc._executor_triggered = True

                # ready waitables (node by node, in each node's order), checked before the wait set is destroyed
                is_ready = wait_set.is_ready
                ready_events = {id(wt) for wt, _node, _h in events
                                if wt._ready_to_take_data or is_ready('event', wt._event_index)}
                in_set = ready_events | {id(wt) for wt, _node in others}
                for wt, node in snap.waitables:
                    if (id(wt) in in_set and wt.is_ready(wait_set) and wt.callback_group.can_execute(wt)):
                        yielded_work = True
                        yield self._make_handler(wt, node, self._take_waitable), wt, node
            finally:
                _exit_each(entered)

            # ready entities one node at a time, in rclpy's order
            rank = snap.rank
            ready = [rank[p] for ps in (timers_ready, subs_ready, clients_ready, services_ready)
                     for p in ps if p in rank]
            ready.extend(g for g in snap.guard_rank if g[2]._executor_triggered)
            ready.sort(key=lambda x: x[0])
            for _r, kind, entity, node in ready:
                if kind == _TIMER and not entity.handle.is_timer_ready():
                    continue
                if kind == _GUARD and not entity._executor_triggered:
                    continue
                if entity.callback_group.can_execute(entity):
                    yielded_work = True
                    if kind <= _SUB and _plain(entity):
                        yield _Call(entity, kind), entity, node
                    else:
                        yield self._make_handler(entity, node, self._take(kind)), entity, node

            if timeout_nsec == 0 or (timeout_timer is not None and timeout_timer.handle.pointer in timers_ready):
                raise TimeoutException()
        if self._is_shutdown:
            raise ShutdownException()
        if condition():
            raise ConditionReachedException()


class _Call:
    """The handler of a ready timer or subscription whose callback is a plain function: takes and runs it when called,
    with the part of rclpy's ``Task`` interface that ``spin_once`` and ``Graph.spin_until_idle`` use (call,
    ``exception``, ``result``, ``done``). rclpy instead wraps every callback in a ``Task`` over two coroutines and
    triggers the executor's guard condition twice; with one thread running one callback at a time, every callback group
    is free and the handler runs before the next wait, so none of that changes what runs or in which order."""

    __slots__ = ("_entity", "_kind", "_exc", "_done")

    def __init__(self, entity: Any, kind: int) -> None:
        self._entity, self._kind, self._exc, self._done = entity, kind, None, False

    def __call__(self) -> None:
        if self._done:
            return
        self._done = True
        e = self._entity
        try:
            try:
                with e.handle:
                    if self._kind == _TIMER:
                        e.handle.call_timer()
                        args: tuple = ()
                    else:
                        taken = e.handle.take_message(e.msg_type, e.raw)
                        if taken is None:
                            return
                        args = taken[:1] if e._callback_type is _MESSAGE_ONLY else taken
            except InvalidHandle:  # destroyed meanwhile: nothing to run, as rclpy
                return
            e.callback(*args)
        except Exception as exc:  # noqa: BLE001 - kept for the caller, as rclpy's Task keeps it
            self._exc = exc

    def exception(self) -> Exception | None:
        return self._exc

    def result(self) -> None:
        if self._exc is not None:
            raise self._exc

    def done(self) -> bool:
        return self._done


def _plain(entity: Any) -> bool:
    """The entity's callback is a plain function (not a coroutine function), asked once per callback object."""
    cb = entity.callback
    c = entity.__dict__.get("_lean_plain")
    if c is None or c[0] is not cb:
        c = entity.__dict__["_lean_plain"] = (cb, not inspect.iscoroutinefunction(cb))
    return c[1]
