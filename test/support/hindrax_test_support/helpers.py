"""Small helpers of a few tests: real-time priority, a counted burst's QoS, single raw transactions."""
from __future__ import annotations

import os
import resource
from typing import Any

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from hindrax_msgs.msg import RawDeviceData

from hindrax_common.node_support.node_common import RAW_BATCH_REGISTER, raw_transactions


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
