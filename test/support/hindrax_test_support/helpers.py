"""Small helpers of a few tests: real-time priority, a counted burst's QoS, single raw
transactions, fresh ROS domains, a command asked again until it succeeds."""
from __future__ import annotations

import contextlib
import itertools
import os
import resource
import subprocess
from typing import Any, Callable, Iterator

from domain_coordinator import domain_id
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from hindrax_msgs.msg import RawDeviceData

from hindrax_common.node_support.node_common import RAW_BATCH_REGISTER, raw_transactions
from hindrax_common.testing import ConditionTimeout, wait_until


def may_set_fifo(priority: int) -> bool:
    """Whether this test's own user may set ``SCHED_FIFO`` at ``priority`` (sched(7), "Privileges and resource
    limits"): root (``CAP_SYS_NICE``), or an ``RLIMIT_RTPRIO`` at least the priority."""
    return os.geteuid() == 0 or resource.getrlimit(resource.RLIMIT_RTPRIO)[0] >= priority


def burst_qos() -> QoSProfile:
    """Publisher QoS for a test that publishes a numbered burst to another process and counts it there: reliable,
    keep-all, transient-local.

    ``publisher.get_subscription_count() > 0`` says only that the writer has matched the reader; the reader may
    match the writer later, and a volatile reader then loses what was published in between (Fast-DDS issues
    2641 and 3009). A transient-local reader (the recorder subscribes so when every publisher offers it,
    ``recording.qos``) receives the writer's history when it matches, so the whole burst arrives either way."""
    return QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def unbatch_raw(msg: Any) -> list:
    """One RawDeviceData per I2C transaction of ``msg`` (itself when it is not a batch; header, device and
    transport copied), for tests that look at single transactions."""
    if int(msg.i2c_register) != RAW_BATCH_REGISTER:
        return [msg]
    return [RawDeviceData(header=msg.header, device_name=msg.device_name, transport=msg.transport, direction=d,
                          i2c_address=a, i2c_register=r, data=data) for d, a, r, data in raw_transactions(msg)]


#: the ROS domain IDs :func:`fresh_domain` hands out: above the xdist workers' own (conftest.py:
#: 2-28) and the lowest free ones ``hindrax run`` reserves (``run_domain``), within ROS 2's 0-101
FRESH_DOMAINS = range(40, 102)
#: where this process's next :func:`fresh_domain` starts looking (first: from the process ID)
_next_domain = itertools.count(os.getpid())


@contextlib.contextmanager
def fresh_domain() -> Iterator[int]:
    """A ROS domain ID for one test (a topside, a second vehicle), held for the block by
    ``domain_coordinator``'s port lock as the workers' domains are, so no concurrent process gets
    it. The IDs tried go round :data:`FRESH_DOMAINS` from where this process's last call stopped,
    so a test never gets the domain an earlier test of its worker just left, as
    ``domain_coordinator``'s lowest-free choice gives: a suite run on 2 cores had ``hindrax bringup
    --sim`` refused on a fresh domain for an ``ESC /esc`` beside the test's own supervisor
    (2026-11-29). Raises RuntimeError when every ID of :data:`FRESH_DOMAINS` is taken."""
    with domain_id(lambda: FRESH_DOMAINS[next(_next_domain) % len(FRESH_DOMAINS)]) as did:
        yield did


def until_done(call: Callable[[], subprocess.CompletedProcess], what: str,
               wait: Callable[[Callable[[], bool], str], None] | None = None,
               timeout_s: float = 180.0) -> subprocess.CompletedProcess:
    """Run ``call`` (a ``hindrax`` command) again until it exits 0, as an operator asks again: the
    ESC refuses to arm until its neutral period and the heartbeats are in (each try is a command,
    not a sleep). ``wait(condition, what)`` is the caller's waiter (one that spins its node and
    attaches the launch's logs on a timeout); default ``wait_until`` within ``timeout_s``. Returns
    the answer; raises AssertionError naming the number of tries and the last answer (a fresh
    clone's suite once timed out on the rehearsal's second arm, 180 s, without saying why:
    2026-11-29)."""
    tries: list[subprocess.CompletedProcess] = []

    def done() -> bool:
        tries.append(call())
        return tries[-1].returncode == 0
    try:
        (wait or (lambda condition, w: wait_until(condition, timeout_s, None, w)))(done, what)
    except (ConditionTimeout, AssertionError) as exc:
        last = tries[-1] if tries else None
        said = f"exit {last.returncode}: {last.stdout}{last.stderr}" if last else "nothing"
        raise AssertionError(f"{exc}\n{what}: {len(tries)} tries, the last answered {said}") \
            from exc
    return tries[-1]
