"""Raw device data batched (node_common.RawDataPublisher): I2C read cycles together for up to 0.1 s (one cycle per
message with a zero period), unpacked again by raw_transactions and by the replay's I2C grouping, in wire order;
a serial report's chunks concatenated."""
import pytest

from hindrax_common.node_support.node_common import (RAW_BATCH_REGISTER, RAW_I2C_PERIOD_S, RawDataPublisher,
                                                      raw_transactions)
from hindrax_test_support.replay_devices import i2c_transactions
from hindrax_msgs.msg import RawDeviceData

READ, WRITE = RawDeviceData.DIRECTION_DEVICE_TO_HOST, RawDeviceData.DIRECTION_HOST_TO_DEVICE


class _Clock:
    """ROS time the test sets (``t_ns``)."""

    def __init__(self):
        self.t_ns = 1_000_000_002

    def now(self):
        t_ns = self.t_ns

        class _T:
            nanoseconds = t_ns

            def to_msg(self):
                from builtin_interfaces.msg import Time
                return Time(sec=t_ns // 10**9, nanosec=t_ns % 10**9)
        return _T()


class _Node:
    """Just what RawDataPublisher uses of a node: create_publisher and get_clock."""

    def __init__(self):
        self.sent = []
        self.clock = _Clock()

    def create_publisher(self, _type, _topic, _depth):
        node = self

        class _Pub:
            def publish(self, msg):
                node.sent.append(msg)
        return _Pub()

    def get_clock(self):
        return self.clock


def test_i2c_cycle_is_one_message_and_unpacks_in_wire_order():
    node = _Node()
    raw = RawDataPublisher(node, "ms5837", i2c_period_s=0.0)  # no period: one message per cycle
    raw.begin_batch()
    raw.i2c_tap("write", 0x76, 0x48, b"")
    raw.i2c_tap("read", 0x76, 0x00, b"\x01\x02\x03")
    raw.i2c_tap("write", 0x76, 0x58, b"")
    raw.i2c_tap("read", 0x76, 0x00, b"\x04\x05\x06")
    assert node.sent == []  # nothing before the flush
    raw.flush()
    assert len(node.sent) == 1
    m = node.sent[0]
    assert m.i2c_register == RAW_BATCH_REGISTER and m.transport == RawDeviceData.TRANSPORT_I2C
    assert raw_transactions(m) == [(WRITE, 0x76, 0x48, b""), (READ, 0x76, 0x00, b"\x01\x02\x03"),
                                   (WRITE, 0x76, 0x58, b""), (READ, 0x76, 0x00, b"\x04\x05\x06")]
    # the replay sees the same transactions as from four separate messages
    tr = i2c_transactions([(0, m)])[0x76]
    assert tr.reads == {0x00: [b"\x01\x02\x03", b"\x04\x05\x06"]} and tr.writes == [b"\x48", b"\x58"]
    # after the flush, taps are published at once again, as plain messages
    raw.i2c_tap("read", 0x76, 0xA0, b"\x00\x01")
    assert len(node.sent) == 2 and node.sent[1].i2c_register == 0xA0
    assert raw_transactions(node.sent[1]) == [(READ, 0x76, 0xA0, b"\x00\x01")]


def test_single_transaction_batch_stays_a_plain_message():
    node = _Node()
    raw = RawDataPublisher(node, "icm20948", i2c_period_s=0.0)
    raw.begin_batch()
    raw.i2c_tap("read", 0x69, 0x2D, bytes(range(23)))
    raw.flush()
    raw.flush()  # nothing left: nothing published
    assert len(node.sent) == 1 and node.sent[0].i2c_register == 0x2D and bytes(node.sent[0].data) == bytes(range(23))


def test_i2c_cycles_are_published_together_once_their_period_is_over():
    # three cycles within the default 0.5 s stay pending, the cycle that ends past it publishes all
    # four in wire order; force publishes what is pending at once; a tap outside a batch takes the pending along
    node = _Node()
    raw = RawDataPublisher(node, "icm20948")
    assert raw.i2c_period_s == RAW_I2C_PERIOD_S == 0.5
    for k in range(4):
        raw.begin_batch()
        raw.i2c_tap("read", 0x69, 0x1A, bytes([k]))
        raw.i2c_tap("read", 0x69, 0x2D, bytes([k, k]))
        raw.flush()
        assert len(node.sent) == (0 if k < 3 else 1)
        node.clock.t_ns += 170_000_000  # 170 ms later (0.51 s after the first cycle at k = 3)
    assert raw_transactions(node.sent[0]) == [(READ, 0x69, r, bytes([k] * n)) for k in range(4)
                                              for r, n in ((0x1A, 1), (0x2D, 2))]
    assert raw.pending_bytes == 0
    raw.begin_batch()
    raw.i2c_tap("read", 0x69, 0x2D, b"\x09")
    raw.flush()
    assert len(node.sent) == 1 and raw.pending_bytes > 0
    raw.flush(force=True)
    assert len(node.sent) == 2 and raw_transactions(node.sent[1]) == [(READ, 0x69, 0x2D, b"\x09")]
    raw.begin_batch()
    raw.i2c_tap("read", 0x69, 0x2D, b"\x0a")
    raw.flush()
    raw.i2c_tap("write", 0x69, 0x7F, b"\x20")  # outside a batch (a bank select of a start-up step)
    assert len(node.sent) == 3
    assert raw_transactions(node.sent[2]) == [(READ, 0x69, 0x2D, b"\x0a"), (WRITE, 0x69, 0x7F, b"\x20")]
    # at shutdown (RosProcess's clean-up after the node's close(): the ESC's neutral write) nothing stays held
    raw.begin_batch()
    raw.i2c_tap("write", 0x40, 0x06, b"\x00\x00\x33\x01")
    raw.flush()
    assert len(node.sent) == 3 and raw.pending_bytes > 0
    raw.flush_pending()
    assert raw.pending_bytes == 0 and raw_transactions(node.sent[3]) == [(WRITE, 0x40, 0x06, b"\x00\x00\x33\x01")]


def test_serial_chunks_concatenate_and_a_write_flushes_first():
    node = _Node()
    raw = RawDataPublisher(node, "dvl75")
    raw.begin_batch()
    raw.serial_tap("rx", b"$DVPDL,1,")
    raw.serial_tap("rx", b"2,3*00\r\n")
    raw.serial_tap("tx", b"wcr\n")
    raw.serial_tap("rx", b"ok\r\n")
    raw.flush(end_batch=False)
    assert [(m.direction, bytes(m.data)) for m in node.sent] == [
        (READ, b"$DVPDL,1,2,3*00\r\n"), (WRITE, b"wcr\n"), (READ, b"ok\r\n")]


def test_truncated_batch_is_an_error():
    import pytest

    m = RawDeviceData(device_name="ms5837", transport=RawDeviceData.TRANSPORT_I2C, i2c_register=RAW_BATCH_REGISTER,
                      data=b"\x00\x76\x00\x00\x05\x00\x01")
    with pytest.raises(ValueError, match="runs past the end"):
        raw_transactions(m)


def test_unbatch_raw_gives_one_message_per_transaction():
    from hindrax_test_support.helpers import unbatch_raw

    node = _Node()
    raw = RawDataPublisher(node, "icm20948")
    raw.begin_batch()
    raw.i2c_tap("read", 0x69, 0x2D, bytes(23))
    raw.i2c_tap("read", 0x69, 0x17, b"\x00")
    raw.flush(force=True)
    parts = unbatch_raw(node.sent[0])
    assert [(m.direction, m.i2c_address, m.i2c_register, len(m.data)) for m in parts] == [
        (READ, 0x69, 0x2D, 23), (READ, 0x69, 0x17, 1)]
    assert all(m.device_name == "icm20948" and m.transport == RawDeviceData.TRANSPORT_I2C for m in parts)
    plain = RawDeviceData(i2c_register=0x2D)
    assert unbatch_raw(plain) == [plain]


def test_after_close_or_with_the_context_gone_nothing_is_published_and_nothing_raises():
    """A transport thread's last records at shutdown (the ESC's neutral written by its chip worker after
    rclpy.shutdown, or after the node was destroyed): dropped, not raised in that thread."""
    node = _Node()

    class _Gone:
        def ok(self):
            return False

    def fail(_msg):
        raise RuntimeError("publisher's context is invalid")
    raw = RawDataPublisher(node, "pca9685", i2c_period_s=0.0)
    raw.publisher.publish = fail
    node.context = _Gone()
    raw.i2c_tap("write", 0x40, 0x06, b"\x00\x00\xdc\x05")  # no exception
    node.context.ok = lambda: True
    with pytest.raises(RuntimeError, match="context is invalid"):  # with the context up a failed publish is a fault
        raw.i2c_tap("write", 0x40, 0x06, b"\x00\x00\xdc\x05")
    raw.close()
    raw.i2c_tap("write", 0x40, 0x06, b"\x00\x00\xdc\x05")  # would raise (fail) if it were published
    raw.flush_pending()
