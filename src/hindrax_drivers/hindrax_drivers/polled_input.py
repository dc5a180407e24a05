"""Subscriptions that no executor dispatches: their owner takes what has arrived when it chooses.

Why (docs/architecture.md §10): a subscription in an executor costs one executor wake-up per message (the DDS
listener hands the message to the executor thread, whose caches are cold by then), and that wake-up, not the
callback, is most of a message's cost here. A node that needs its messages only every so often (the recorder
writes them to disk; nothing waits for a single one) saves about half of its receive cost by taking them in
batches from a timer: measured with a 600 msg/s publisher process and a raw subscriber process spinning the
EventsExecutor, 2.3-2.5 % of a core with one callback per message, 1.2-1.3 % with a 20 Hz timer taking every
queued message.

How: rclpy has no such mode, and every subscription of a node added to an executor is dispatched by it. So the
subscriptions live on a second node, ``<owner>_intake``, that is added to no executor (it ignores the process's
global arguments, so a ``-r __node:=`` remap of the owner does not rename it too). :meth:`PolledSubscriptions.take`
takes the queued messages with the subscription handle's ``take_message``, the call rclpy's own executors make
for each message. Each message comes with its ``rmw_message_info`` (a dict: ``source_timestamp`` and
``received_timestamp``, ns of the system clock, as rclpy's executors pass to ``(msg, info)`` callbacks). The QoS
depth of each subscription must hold what arrives between two takes.

A node whose topic inputs are polled at its own tick (the ESC, the output guard, the supervisor, the identification
node, the controller) takes :class:`PolledInputsMixin`: it opens them (:class:`PolledInputs` on the system clock,
callbacks with ``use_sim_time``), takes them at the tick after what must run first (the heartbeat ages' ticks), and
closes them with the node.
"""
from __future__ import annotations

import time
from typing import Any, Callable, Iterable, Iterator

from rclpy.node import Node

from .lean_cdr import cdr_decoder

__all__ = ["PolledInputs", "PolledInputsMixin", "PolledSubscriptions", "polled_inputs", "received_ago_s",
           "subscribe_input"]


class PolledSubscriptions:
    """Subscriptions on a node of their own that no executor spins (module docstring).

    owner: the node that takes the messages (its name, namespace and context are used; the intake node is
    ``<owner name>_intake``). Call :meth:`close` when done (destroys the intake node and its subscriptions).
    """

    def __init__(self, owner: Node) -> None:
        self.node = Node(f"{owner.get_name()}_intake", namespace=owner.get_namespace(), context=owner.context,
                         use_global_arguments=False, start_parameter_services=False, enable_rosout=False)

    def subscribe(self, msg_type: Any, topic: str, qos: Any, raw: bool = False, **kwargs: Any) -> Any:
        """A subscription (rclpy ``Subscription``) to ``topic`` whose messages :meth:`take` returns; ``raw``: CDR
        bytes instead of a message object; other keyword arguments go to ``create_subscription``."""
        return self.node.create_subscription(msg_type, topic, _never_called, qos, raw=raw, **kwargs)

    @staticmethod
    def take(subscription: Any) -> Iterator[tuple[Any, dict]]:
        """Every message queued on ``subscription`` now, oldest first, as ``(message or CDR bytes, info)``; info
        holds ``source_timestamp`` and ``received_timestamp`` (ns, system clock; 0 where the middleware gave
        none)."""
        while True:
            with subscription.handle:
                taken = subscription.handle.take_message(subscription.msg_type, subscription.raw)
            if taken is None:
                return
            yield taken[0], taken[1]

    def destroy(self, subscription: Any) -> None:
        """Destroy one subscription of :meth:`subscribe`."""
        self.node.destroy_subscription(subscription)

    def close(self) -> None:
        """Destroy the intake node and every subscription on it."""
        self.node.destroy_node()


class PolledInputs(PolledSubscriptions):
    """Polled subscriptions with a handler each: a node's topic inputs taken at its own tick (the supervisor, the
    identification node, the controller on the system clock; docs/architecture.md §10.1).

    :meth:`take_all` hands every queued message to its handler, subscription by subscription, and sets
    :attr:`received_s` to the message's DDS reception time (s, system clock; None where the middleware gave none)
    while the handler runs, so a handler can count a sample at its arrival as a callback would have.
    """

    def __init__(self, owner: Node) -> None:
        super().__init__(owner)
        self.handlers: dict[Any, Callable[[Any], None]] = {}
        #: DDS reception time of the message being handled by :meth:`take_all`, s; None outside it
        self.received_s: float | None = None

    def received_ago_s(self) -> float:
        """Wall time since the DDS reception of the message being handled by :meth:`take_all`, s (system clock,
        >= 0); 0.0 outside it or where the middleware gave no reception time (the message counts as heard now)."""
        if self.received_s is None:
            return 0.0
        return max(0.0, time.time() - self.received_s)

    def add(self, msg_type: Any, topic: str, handler: Callable[[Any], None], qos: Any, raw: bool = False,
            lean: bool = False, **kwargs: Any) -> Any:
        """:meth:`subscribe` ``topic`` with ``handler`` for :meth:`take_all`; returns the subscription. ``lean``: the
        message is taken as CDR bytes and handed over as rosbags' light decoding of them
        (:func:`hindrax_drivers.lean_cdr.cdr_decoder`: the ROS field names, read-only) instead of an rclpy object,
        for a handler that only reads fields (about 31 instead of 77 us per ``Imu``, that module's docstring)."""
        if lean and not raw:
            decode = cdr_decoder(msg_type)
            sub = self.subscribe(msg_type, topic, qos, raw=True, **kwargs)
            self.handlers[sub] = lambda data: handler(decode(data))
            return sub
        sub = self.subscribe(msg_type, topic, qos, raw=raw, **kwargs)
        self.handlers[sub] = handler
        return sub

    def remove(self, subscription: Any) -> None:
        """Destroy one subscription of :meth:`add`; a :meth:`take_all` under way hands it nothing more."""
        self.handlers.pop(subscription, None)
        self.destroy(subscription)

    def take_all(self) -> int:
        """Hand every queued message to its handler (oldest first per subscription). Returns how many."""
        n = 0
        try:
            for sub, handler in list(self.handlers.items()):
                if sub not in self.handlers:  # removed by a handler of this round: destroyed, nothing to take
                    continue
                for msg, info in self.take(sub):
                    received_ns = info.get("received_timestamp") or 0
                    self.received_s = received_ns * 1e-9 if received_ns else None
                    handler(msg)
                    n += 1
                    if sub not in self.handlers:
                        break
        finally:
            self.received_s = None
        return n

    def close(self) -> None:
        """Forget the handlers and destroy the intake node."""
        self.handlers.clear()
        super().close()


class PolledInputsMixin:
    """For a node whose topic inputs are taken at its own tick on the system clock (module docstring): listed before
    ``Node`` in its bases (``class EscNode(PolledInputsMixin, Node)``).

    :meth:`open_inputs` creates the inputs (:func:`polled_inputs`: None with ``use_sim_time``) in an attribute of the
    node's choice, :meth:`take_inputs` takes them at the tick after the ``before_take`` hooks, and
    :meth:`destroy_node` closes them (their intake node) before the node itself is destroyed.
    """

    _inputs_attribute: str | None = None
    _before_take: tuple[Callable[[], Any], ...] = ()

    def open_inputs(self, attribute: str = "inputs",
                    before_take: Iterable[Callable[[], Any]] = ()) -> PolledInputs | None:
        """Set ``self.<attribute>`` to :func:`polled_inputs` of this node and return it (None with ``use_sim_time``:
        its inputs are callbacks, :func:`subscribe_input`). ``before_take``: called, in order, at the start of every
        :meth:`take_inputs`, polled or not: a heartbeat age's ``AliveAge.tick``, so that a beat taken right after it
        counts from its reception (:func:`received_ago_s`)."""
        inputs = polled_inputs(self)  # a Node: the mixin precedes Node in its bases
        setattr(self, attribute, inputs)
        self._inputs_attribute, self._before_take = attribute, tuple(before_take)
        return inputs

    def take_inputs(self) -> int:
        """Run the ``before_take`` hooks of :meth:`open_inputs`, then hand every message queued on the polled inputs
        to its handler (:meth:`PolledInputs.take_all`). Returns how many; 0 with ``use_sim_time`` (callbacks)."""
        for hook in self._before_take:
            hook()
        inputs = self._inputs()
        return inputs.take_all() if inputs is not None else 0

    def destroy_node(self) -> None:
        """Close the polled inputs (destroys their intake node; the attribute becomes None), then destroy the node."""
        inputs = self._inputs()
        if inputs is not None:
            inputs.close()
            setattr(self, str(self._inputs_attribute), None)
        super().destroy_node()  # Node's, next in the bases

    def _inputs(self) -> PolledInputs | None:
        return getattr(self, self._inputs_attribute) if self._inputs_attribute is not None else None


def subscribe_input(node: Node, inputs: PolledInputs | None, msg_type: Any, topic: str,
                    handler: Callable[[Any], None], qos: Any, raw: bool = False, lean: bool = False,
                    **kwargs: Any) -> Any:
    """One topic input of ``node``: a callback subscription when ``inputs`` is None (``use_sim_time``: the stepped
    simulation dispatches every message in order; ``lean`` does not apply, the handler gets rclpy objects), else
    polled on ``inputs`` (:meth:`PolledInputs.add`, ``lean`` included): a ``lean`` handler must read fields only."""
    if inputs is None:
        return node.create_subscription(msg_type, topic, handler, qos, raw=raw, **kwargs)
    return inputs.add(msg_type, topic, handler, qos, raw=raw, lean=lean, **kwargs)


def polled_inputs(node: Node) -> PolledInputs | None:
    """:class:`PolledInputs` for ``node`` on the system clock; None with ``use_sim_time`` (its inputs are
    callbacks)."""
    return None if node.get_parameter("use_sim_time").value else PolledInputs(node)


def received_ago_s(inputs: PolledInputs | None) -> float:
    """Wall time since the message being handled was received, s: :meth:`PolledInputs.received_ago_s` for a handler
    called by ``inputs.take_all``, 0.0 when ``inputs`` is None (a callback runs at the message's arrival). The safety
    nodes age a heartbeat by it (:meth:`hindrax_drivers.liveness.AliveAge.heard`), so a beat taken at their tick
    counts from its reception, as a callback would have counted it."""
    return inputs.received_ago_s() if inputs is not None else 0.0


def _never_called(_msg: Any) -> None:  # the intake node is in no executor: nothing dispatches its subscriptions
    raise AssertionError("a polled subscription's callback was called: its intake node was added to an executor")
