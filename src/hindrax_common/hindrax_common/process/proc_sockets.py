"""UDP sockets of a running process, read from Linux's /proc (proc(5): ``/proc/<pid>/net/udp``, ``udp6``, ``fd``).

Used to check that a vehicle participant listens on loopback only (docs/architecture.md §8.2): a socket bound to
127.0.0.1, or to a multicast group (Fast DDS's discovery group, joined on loopback by the transport's white list),
cannot be reached from the tether; one on 0.0.0.0, an interface address or IPv6 can."""
from __future__ import annotations

import os
import socket
import struct
from collections.abc import Iterable
from pathlib import Path

__all__ = ["child_pids", "exposed", "parse_udp_table", "reachable_from_network", "socket_inodes", "udp_sockets"]


def parse_udp_table(text: str, inodes: Iterable[str], ipv6: bool = False) -> list[tuple[str, int]]:
    """(local address, port) of the rows of a ``/proc/<pid>/net/udp`` (``ipv6``: ``udp6``) table ``text`` whose
    inode is in ``inodes``; an IPv4 address as dotted quad, every IPv6 one as ``'ipv6'``."""
    wanted = set(inodes)
    out = []
    for line in text.splitlines()[1:]:
        fields = line.split()
        if len(fields) < 10 or fields[9] not in wanted:
            continue
        address, port = fields[1].split(":")
        out.append(("ipv6" if ipv6 else socket.inet_ntoa(struct.pack("<I", int(address, 16))), int(port, 16)))
    return out


def socket_inodes(pid: int) -> set[str]:
    """Inode numbers (as text) of the sockets process ``pid`` holds open (its ``fd`` links ``socket:[N]``)."""
    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        try:
            target = os.readlink(fd)
        except OSError:  # closed meanwhile
            continue
        if target.startswith("socket:["):
            inodes.add(target[8:-1])
    return inodes


def udp_sockets(pid: int) -> list[tuple[str, int]]:
    """(local address, port) of every UDP socket process ``pid`` holds (IPv6 ones as ``('ipv6', port)``).
    Raises OSError when the process is gone."""
    inodes = socket_inodes(pid)
    return [s for table, v6 in (("udp", False), ("udp6", True))
            for s in parse_udp_table(Path(f"/proc/{pid}/net/{table}").read_text(), inodes, ipv6=v6)]


def reachable_from_network(address: str) -> bool:
    """True when a UDP socket bound to ``address`` (as :func:`udp_sockets` gives it) can receive from another
    machine: anything but 127.0.0.1 and an IPv4 multicast group (224.0.0.0/4)."""
    if address == "127.0.0.1":
        return False
    return address == "ipv6" or not 224 <= int(address.split(".")[0]) <= 239


def exposed(sockets_by_process: dict[str, list[tuple[str, int]]]) -> dict[str, list[tuple[str, int]]]:
    """The sockets of ``sockets_by_process`` (process label -> :func:`udp_sockets`) reachable from the network,
    per process that has any."""
    out = {name: [s for s in sockets if reachable_from_network(s[0])] for name, sockets in sockets_by_process.items()}
    return {name: sockets for name, sockets in out.items() if sockets}


def child_pids(pid: int) -> list[int]:
    """Process ids of the children of ``pid`` (its main thread's, /proc/<pid>/task/<pid>/children); [] when gone."""
    try:
        return [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []
