"""Signed operator commands: a per-vehicle secret, HMAC-SHA256 signatures, a rising timestamp per link.

Modelled on MAVLink 2 message signing (mavlink.io, "Message Signing"): a 32-byte secret shared by the vehicle and
the operator's PC, a *link id* (one byte, one per sender), a 48-bit *timestamp* in 10 us units since
2015-01-01 00:00 UTC that must rise on each link, and a MAC over the message. Differences: the MAC is the full
HMAC-SHA256 (Python's :mod:`hmac`) rather than SHA-256 truncated to 48 bits, and it covers the vehicle name and the
relay's name (``arm`` and ``disarm`` have the same empty request: a signed disarm cannot be replayed as an arm).

The gateway (:mod:`hindrax_drivers.gateway.node`) checks every operator request with a :class:`Verifier`; the
``hindrax`` command signs with a :class:`Signer` when it has the key (:func:`key_path`). The e-stop is never signed.

Key file: ``<keys dir>/<vehicle>.key`` (:func:`key_path`), 64 hex digits and a newline, mode 0600, on the vehicle and
on the operator's PC. Made by :func:`create_key` (``hindrax keys``).

Pure: standard library only (messages are read through their fields).
"""
from __future__ import annotations

import hmac
import json
import os
import secrets
import stat
import threading
import time
from dataclasses import dataclass, field
from hashlib import sha256
from pathlib import Path
from typing import Any, Callable

__all__ = ["KEYS_DIR_ENV", "KEY_BYTES", "NEW_LINK_WINDOW", "OperatorKeyError", "Signature", "Signer", "Verifier",
           "create_key", "key_path", "keys_dir", "load_key", "mac", "signed_payload", "timestamp_now"]

#: the secret's length, bytes (MAVLink 2: 32)
KEY_BYTES = 32
#: the environment variable naming the keys folder (default ``~/.config/hindrax/keys``)
KEYS_DIR_ENV = "HINDRAX_KEYS_DIR"
#: MAVLink's epoch: 2015-01-01 00:00:00 UTC, Unix seconds
EPOCH_S = 1420070400
#: the timestamp's largest value (48 bits)
TIMESTAMP_MAX = (1 << 48) - 1
#: a link not seen before is accepted when its first timestamp is no older than this below the newest timestamp
#: accepted on any link and the vehicle's clock (MAVLink: one minute), in timestamp units (10 us)
NEW_LINK_WINDOW = 60 * 100_000
#: what is signed starts with this (domain separation from any other use of the key)
_CONTEXT = b"hindrax-operator-v1\0"


class OperatorKeyError(ValueError):
    """A key file that is missing, malformed or readable by others: one line naming the file and the fix."""


def keys_dir() -> Path:
    """The folder of key files: ``$HINDRAX_KEYS_DIR``, else ``~/.config/hindrax/keys``."""
    return Path(os.environ.get(KEYS_DIR_ENV) or Path.home() / ".config" / "hindrax" / "keys")


def key_path(vehicle: str) -> Path:
    """The key file of vehicle ``vehicle`` (its ``vehicle.name``)."""
    return keys_dir() / f"{vehicle}.key"


def create_key(path: Path, force: bool = False) -> Path:
    """Write a new random 32-byte key (:func:`secrets.token_bytes`) to ``path`` as hex, mode 0600 from creation;
    the folder is made (mode 0700) if missing. Raises :class:`OperatorKeyError` when the file exists and not
    ``force``."""
    path = Path(path)
    if path.exists() and not force:
        raise OperatorKeyError(f"{path} exists (a new key means copying it to the topside again): use --force to "
                               "replace it")
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    tmp = path.with_name(path.name + ".new")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(secrets.token_bytes(KEY_BYTES).hex() + "\n")
    os.chmod(tmp, 0o600)
    os.replace(tmp, path)
    return path


def load_key(path: Path) -> bytes:
    """The 32-byte key in ``path``. Raises :class:`OperatorKeyError` (one line) when missing, not 64 hex digits, or
    readable or writable by group or others (as ssh refuses such a private key)."""
    path = Path(path)
    try:
        mode = path.stat().st_mode
        text = path.read_text().strip()
    except OSError as exc:
        raise OperatorKeyError(f"operator key {path}: {exc.strerror or exc} (create it with `hindrax keys`)") from None
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise OperatorKeyError(f"operator key {path}: mode {stat.S_IMODE(mode):04o} lets others read it: "
                               f"chmod 600 {path}")
    try:
        key = bytes.fromhex(text)
    except ValueError:
        key = b""
    if len(key) != KEY_BYTES:
        raise OperatorKeyError(f"operator key {path}: not {2 * KEY_BYTES} hex digits (create it with `hindrax keys`)")
    return key


def timestamp_now() -> int:
    """Now as a signing timestamp: 10 us units since 2015-01-01 00:00 UTC (48 bits)."""
    return min(TIMESTAMP_MAX, max(0, (time.time_ns() // 10_000) - EPOCH_S * 100_000))


def mac(key: bytes, vehicle: str, relay: str, link_id: int, timestamp: int, payload: bytes) -> bytes:
    """HMAC-SHA256 (32 bytes) of one request: vehicle name, relay name (``arm``, ``controller/setpoint``...), link
    id, 48-bit timestamp and ``payload`` (the request serialized with its signature field empty)."""
    head = _CONTEXT + vehicle.encode() + b"\0" + relay.encode() + b"\0" + bytes([link_id & 0xFF]) \
        + (timestamp & TIMESTAMP_MAX).to_bytes(6, "little")
    return hmac.new(key, head + payload, sha256).digest()


def signed_payload(message: Any) -> bytes:
    """The bytes a signature covers: every field of ``message`` (a ROS message or request) but its ``signature``,
    in declaration order, nested messages and arrays included, in a canonical text form (floats as
    :meth:`float.hex`, strings as JSON). Not the CDR serialization: Fast CDR leaves alignment padding uninitialised,
    so two serializations of one message may differ."""
    if hasattr(message, "get_fields_and_field_types"):
        return b"{" + b",".join(key.encode() + b"=" + signed_payload(getattr(message, key))
                                for key in message.get_fields_and_field_types() if key != "signature") + b"}"
    if isinstance(message, (bytes, bytearray)):
        return b"x" + bytes(message).hex().encode()
    if isinstance(message, str):
        return json.dumps(message).encode()
    if hasattr(message, "tolist"):  # numpy arrays and array.array
        message = message.tolist()
    if isinstance(message, (list, tuple)):
        return b"[" + b",".join(signed_payload(v) for v in message) + b"]"
    if isinstance(message, float):
        return float(message).hex().encode()
    return repr(message).encode()


@dataclass(frozen=True)
class Signature:
    """A signature's fields: ``link_id`` (0-255), ``timestamp`` (48-bit, 10 us units), ``mac`` (32 bytes)."""

    link_id: int
    timestamp: int
    mac: bytes


class Signer:
    """Signs the requests of one sender (one link): ``link_id`` random unless given; each :meth:`sign` takes a
    timestamp above the previous one (wall clock, else previous + 1)."""

    def __init__(self, key: bytes, vehicle: str, link_id: int | None = None) -> None:
        self.key, self.vehicle = key, vehicle
        self.link_id = secrets.randbelow(256) if link_id is None else link_id
        self._last = 0

    def sign(self, relay: str, payload: bytes) -> Signature:
        """The signature of ``payload`` sent to relay ``relay``."""
        self._last = max(timestamp_now(), self._last + 1)
        return Signature(self.link_id, self._last, mac(self.key, self.vehicle, relay, self.link_id, self._last,
                                                       payload))

    def sign_message(self, relay: str, message: Any) -> Any:
        """Fill ``message.signature`` (hindrax_msgs/Signature) for relay ``relay``; returns ``message``."""
        sig = self.sign(relay, signed_payload(message))
        message.signature.link_id, message.signature.timestamp = sig.link_id, sig.timestamp
        message.signature.mac = list(sig.mac)
        return message


@dataclass
class Verifier:
    """Checks operator requests for one vehicle (the gateway): ``key`` None = no key on the vehicle, every request
    refused. :meth:`check` returns None (accepted) or the one-line reason; ``counts`` has ``accepted``,
    ``unsigned``, ``bad_signature``, ``replayed`` and ``no_key``. ``now``: the vehicle's clock as a timestamp
    (chrony keeps the Pi on the topside's clock); safe to call from several threads."""

    key: bytes | None
    vehicle: str
    now: Callable[[], int] = timestamp_now
    last: dict[int, int] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=lambda: dict.fromkeys(
        ("accepted", "unsigned", "bad_signature", "replayed", "no_key"), 0))
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def check(self, relay: str, signature: Signature, payload: bytes) -> str | None:
        """None when ``signature`` is a valid signature of ``payload`` for ``relay`` with a timestamp above the
        last accepted on its link (a new link: within :data:`NEW_LINK_WINDOW` of the newest on any link); else the
        reason, counted. Only an accepted request moves its link's timestamp."""
        with self._lock:
            return self._check(relay, signature, payload)

    def _check(self, relay: str, signature: Signature, payload: bytes) -> str | None:
        if self.key is None:
            return self._refuse("no_key", f"{relay}: refused: no operator key on the vehicle ({key_path(self.vehicle)};"
                                          " create it with `hindrax keys`)")
        if not any(signature.mac) and signature.timestamp == 0:
            return self._refuse("unsigned", f"{relay}: refused: unsigned (the operator's key is "
                                            f"{key_path(self.vehicle)} on the topside PC)")
        expected = mac(self.key, self.vehicle, relay, signature.link_id, signature.timestamp, payload)
        if not hmac.compare_digest(expected, bytes(signature.mac)):
            return self._refuse("bad_signature", f"{relay}: refused: bad signature (not this vehicle's key)")
        last = self.last.get(signature.link_id)
        floor = last if last is not None else max(max(self.last.values(), default=0), self.now()) - NEW_LINK_WINDOW
        if signature.timestamp <= floor:
            return self._refuse("replayed", f"{relay}: refused: replayed or stale (link {signature.link_id} "
                                            f"timestamp {signature.timestamp} not above {max(floor, 0)}; a new link "
                                            "must be within 60 s of the vehicle's clock)")
        self.last[signature.link_id] = signature.timestamp
        self.counts["accepted"] += 1
        return None

    def check_message(self, relay: str, message: Any) -> str | None:
        """:meth:`check` for a request or message with a ``signature`` field (hindrax_msgs/Signature)."""
        s = message.signature
        return self.check(relay, Signature(int(s.link_id), int(s.timestamp), bytes(s.mac)), signed_payload(message))

    def _refuse(self, kind: str, why: str) -> str:
        self.counts[kind] += 1
        return why
