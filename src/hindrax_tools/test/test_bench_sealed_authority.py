"""The safety bench's authority rows (hindrax_tools.benchmarks.sealed_authority) count what
they claim: a UDP socket
on every address (read from /proc by hindrax_common.process.proc_sockets) and an accepted unsigned request are counted;
loopback and multicast sockets and refused requests are not."""
from __future__ import annotations

import os
import socket

from hindrax_common.process.proc_sockets import parse_udp_table, reachable_from_network, udp_sockets

from hindrax_tools.benchmarks.sealed_authority import exposure_row, signing_rows

#: /proc/net/udp as the kernel writes it: 0.0.0.0:7400 (inode 111), 127.0.0.1:7410 (222), 239.255.0.1:7400 (333)
UDP_TABLE = """\
   sl  local_address rem_address   st tx_queue rx_queue tr tm->when retrnsmt   uid  timeout inode ref pointer drops
  1: 00000000:1CE8 00000000:0000 07 00000000:00000000 00:00000000 00000000  1000        0 111 2 0 0
  2: 0100007F:1CF2 00000000:0000 07 00000000:00000000 00:00000000 00000000  1000        0 222 2 0 0
  3: 0100FFEF:1CE8 00000000:0000 07 00000000:00000000 00:00000000 00000000  1000        0 333 2 0 0
  4: 0100007F:1CF3 00000000:0000 07 00000000:00000000 00:00000000 00000000  1000        0 444 2 0 0
"""


def test_the_table_parser_reads_address_port_of_the_process_inodes_only():
    assert parse_udp_table(UDP_TABLE, {"111", "222", "333"}) == [
        ("0.0.0.0", 7400), ("127.0.0.1", 7410), ("239.255.0.1", 7400)]
    assert parse_udp_table(UDP_TABLE, {"444"}, ipv6=True) == [("ipv6", 7411)]


def test_only_loopback_and_multicast_are_sealed():
    assert [reachable_from_network(a) for a in ("127.0.0.1", "239.255.0.1", "0.0.0.0", "10.77.0.1", "ipv6")] == [
        False, False, True, True, True]


def test_a_socket_on_every_address_is_counted_and_loopback_is_not():
    wild = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    loop = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        wild.bind(("0.0.0.0", 0))
        loop.bind(("127.0.0.1", 0))
        mine = udp_sockets(os.getpid())
        wild_port, loop_port = wild.getsockname()[1], loop.getsockname()[1]
        assert ("0.0.0.0", wild_port) in mine and ("127.0.0.1", loop_port) in mine, mine
        row = exposure_row({"esc": [("127.0.0.1", loop_port), ("239.255.0.1", 7400)],
                            "gateway internal": [("0.0.0.0", wild_port)]})
        assert row["value"] == 1 and row["target"] == 0
        assert "gateway internal" in row["note"] and f"('0.0.0.0', {wild_port})" in row["note"], row["note"]
        assert exposure_row({"esc": [("127.0.0.1", loop_port)]})["value"] == 0
    finally:
        wild.close()
        loop.close()


def test_an_accepted_unsigned_request_is_counted_per_kind():
    rows = {r["name"]: r for r in signing_rows({"unsigned": [False, True, False], "wrong_key": [False] * 3,
                                                "replayed": [True, True, False]})}
    assert rows["operator_unsigned_requests_accepted"]["value"] == 1
    assert rows["operator_wrong_key_requests_accepted"]["value"] == 0
    assert rows["operator_replayed_requests_accepted"]["value"] == 2
    assert rows["operator_replayed_requests_accepted"]["unit"] == "of 3 requests"
