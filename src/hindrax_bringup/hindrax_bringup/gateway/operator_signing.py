"""Signed operator commands: a per-vehicle secret, HMAC-SHA256 signatures, timestamps near the vehicle's clock.

Modelled on MAVLink 2 message signing (mavlink.io, "Message Signing"): a 32-byte secret shared by the vehicle and
the operator's PC, a *link id*, a 48-bit *timestamp* in 10 us units since 2015-01-01 00:00 UTC, a MAC. Past it
(each difference and why: docs/threat_model.md §4): full HMAC-SHA256 over the vehicle and relay names too; a link id
past 255 or a timestamp past 2^48-1 refused before the MAC; a timestamp more than :data:`AHEAD_LIMIT` ahead of or
:data:`STALE_LIMIT` behind the vehicle's clock refused; replays caught by a cache of the MACs seen (those refused for
being ahead included) with a floor for those that left it, written to ``<keys dir>/<vehicle>.replay``
(:func:`replay_path`) before a request is accepted and read at start.

The gateway (:mod:`hindrax_bringup.gateway.node`) checks every operator request with a :class:`Verifier`; the
``hindrax`` command signs with a :class:`Signer` when it has the key (:func:`key_path`). The e-stop is never signed.
A refusal sent to the topside names no file of the vehicle.

Key file: ``<keys dir>/<vehicle>.key`` (:func:`key_path`), 64 hex digits and a newline, mode 0600, on the vehicle and
on the operator's PC. Made by :func:`create_key` (``hindrax keys``).

Pure: standard library only (messages are read through their fields)."""
from __future__ import annotations

import hmac
import json
import os
import secrets
import stat
import threading
import time
from dataclasses import dataclass
from hashlib import sha256
from pathlib import Path
from typing import Any, Callable

__all__ = ["AHEAD_LIMIT", "KEYS_DIR_ENV", "KEY_BYTES", "STALE_LIMIT", "OperatorKeyError", "Signature", "Signer",
           "Verifier", "create_key", "key_path", "keys_dir", "load_key", "mac", "replay_path", "signed_payload",
           "timestamp_now"]

#: the secret's length, bytes (MAVLink 2: 32)
KEY_BYTES = 32
#: the environment variable naming the keys folder (default ``~/.config/hindrax/keys``)
KEYS_DIR_ENV = "HINDRAX_KEYS_DIR"
#: MAVLink's epoch: 2015-01-01 00:00:00 UTC, Unix seconds
EPOCH_S = 1420070400
#: the timestamp's largest value (48 bits)
TIMESTAMP_MAX = (1 << 48) - 1
#: a timestamp further ahead of the vehicle's clock than this is refused (chrony keeps the PC and the Pi within
#: milliseconds), timestamp units (10 us): 5 s
AHEAD_LIMIT = 5 * 100_000
#: a timestamp further behind the vehicle's clock than this is refused (MAVLink's one minute), timestamp units: 60 s
STALE_LIMIT = 60 * 100_000
#: the replay cache's size bound, MACs (at most :data:`AHEAD_MEMORY` of them refused for being ahead)
CACHE_MAX = 4096
#: how many MACs refused for being ahead the cache keeps (a PC with a wrong clock streaming setpoints fills it)
AHEAD_MEMORY = 1024
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


def replay_path(vehicle: str) -> Path:
    """The replay cache of vehicle ``vehicle`` (:class:`Verifier`), next to its key file."""
    return keys_dir() / f"{vehicle}.replay"


def create_key(path: Path, force: bool = False) -> Path:
    """Write a new random 32-byte key (:func:`secrets.token_bytes`) to ``path`` as hex, mode 0600 from creation; the
    folder is made (mode 0700) if missing. Raises :class:`OperatorKeyError` when the file exists and not ``force``."""
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
    id, 48-bit timestamp and ``payload`` (the request serialized with its signature field empty). Raises
    ValueError/OverflowError for a link id outside 0-255 or a timestamp outside 0 - 2^48-1 (none is masked)."""
    head = _CONTEXT + vehicle.encode() + b"\0" + relay.encode() + b"\0" + bytes([link_id]) \
        + timestamp.to_bytes(6, "little")
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


class Verifier:
    """Checks operator requests for one vehicle (the gateway): ``key`` None = no key on the vehicle, every request
    refused. :meth:`check` returns None (accepted) or the one-line reason; ``counts`` has ``accepted``,
    ``unsigned``, ``malformed``, ``bad_signature``, ``ahead``, ``stale``, ``replayed``, ``unrecorded`` (the cache
    could not be written) and ``no_key``. ``now``: the vehicle's clock as a timestamp. ``state``: the replay cache's
    file (:func:`replay_path`; None = memory only); a file that cannot be read leaves everything up to
    now + :data:`AHEAD_LIMIT` refused (``problem`` says why). Safe to call from several threads."""

    def __init__(self, key: bytes | None, vehicle: str, now: Callable[[], int] = timestamp_now,
                 state: Path | None = None) -> None:
        self.key, self.vehicle, self.now, self.state = key, vehicle, now, state
        self.counts = dict.fromkeys(("accepted", "unsigned", "malformed", "bad_signature", "ahead", "stale",
                                     "replayed", "unrecorded", "no_key"), 0)
        self.seen: dict[bytes, int] = {}
        """The replay cache: MAC -> timestamp, of requests accepted or refused for being ahead."""
        self.floor = 0
        """Every timestamp at or below this is refused: the newest that left :attr:`seen`."""
        self.problem = ""
        self._lock = threading.Lock()
        self._load()

    def _load(self) -> None:
        if self.state is None or not self.state.exists():
            return
        try:
            floor, *rows = self.state.read_text().split("\n")
            self.floor = int(floor)
            self.seen = {bytes.fromhex(m): int(t) for t, m in (row.split() for row in rows if row)}
        except (OSError, ValueError) as exc:
            self.floor, self.seen = self.now() + AHEAD_LIMIT, {}
            self.problem = f"replay cache {self.state} unreadable ({exc}): requests up to now + 5 s refused"

    def _save(self) -> bool:
        if self.state is None:
            return True
        text = "\n".join([str(self.floor), *(f"{t} {m.hex()}" for m, t in self.seen.items())]) + "\n"
        tmp = self.state.with_name(f"{self.state.name}.{os.getpid()}.tmp")  # one per writer process
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            with os.fdopen(fd, "w") as f:
                f.write(text)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, self.state)
        except OSError as exc:
            self.problem = f"replay cache {self.state}: {exc.strerror or exc}"
            return False
        return True

    def _remember(self, code: bytes, timestamp: int) -> bool:
        """Put ``code`` in the cache (evicting the oldest past :data:`CACHE_MAX`) and write it; False if unwritten."""
        self.seen[code] = timestamp
        while len(self.seen) > CACHE_MAX:
            oldest = min(self.seen, key=self.seen.__getitem__)
            self.floor = max(self.floor, self.seen.pop(oldest))
        return self._save()

    def check(self, relay: str, signature: Signature, payload: bytes) -> str | None:
        """None when ``signature`` is a valid signature of ``payload`` for ``relay``, its timestamp within
        [now - :data:`STALE_LIMIT`, now + :data:`AHEAD_LIMIT`], above the floor, its MAC not seen before, and the
        cache written; else the reason, counted. A valid request refused for being ahead is remembered too."""
        with self._lock:
            return self._check(relay, signature, payload)

    def _check(self, relay: str, signature: Signature, payload: bytes) -> str | None:
        if self.key is None:
            return self._refuse("no_key", f"{relay}: refused: no operator key on the vehicle (create it there with "
                                          "`hindrax keys`, then copy it to this PC)")
        code, ts, link = bytes(signature.mac), signature.timestamp, signature.link_id
        if not any(code) and ts == 0:
            return self._refuse("unsigned", f"{relay}: refused: unsigned (this PC has no key for {self.vehicle}: "
                                            "copy the vehicle's key here, see `hindrax keys --help`)")
        if not (0 <= link <= 255 and 0 <= ts <= TIMESTAMP_MAX):
            return self._refuse("malformed", f"{relay}: refused: link id {link} or timestamp {ts} out of range "
                                             f"(0-255, 0-{TIMESTAMP_MAX})")
        if not hmac.compare_digest(mac(self.key, self.vehicle, relay, link, ts, payload), code):
            return self._refuse("bad_signature", f"{relay}: refused: bad signature (not this vehicle's key)")
        now = self.now()
        expired = [m for m, t in self.seen.items() if t < now - STALE_LIMIT]
        for m in expired:
            self.floor = max(self.floor, self.seen.pop(m))
        if code in self.seen or ts <= self.floor:
            return self._refuse("replayed", f"{relay}: refused: replayed (link {link} timestamp {ts} seen before "
                                            "or older than the vehicle's replay floor)")
        if ts > now + AHEAD_LIMIT:
            if sum(t > now + AHEAD_LIMIT for t in self.seen.values()) < AHEAD_MEMORY:
                self._remember(code, ts)
            return self._refuse("ahead", f"{relay}: refused: this PC's clock is {(ts - now) / 1e5:.1f} s ahead of "
                                         f"the vehicle's (at most {AHEAD_LIMIT / 1e5:g} s): fix its time (chrony), "
                                         "or the vehicle's if it has not synchronised since boot")
        if ts < now - STALE_LIMIT:
            return self._refuse("stale", f"{relay}: refused: stale: this PC's clock is {(now - ts) / 1e5:.1f} s "
                                         f"behind the vehicle's (at most {STALE_LIMIT / 1e5:g} s): fix its time "
                                         "(chrony), or the request is an old copy")
        if not self._remember(code, ts):
            self.seen.pop(code, None)
            return self._refuse("unrecorded", f"{relay}: refused: the vehicle could not record it against replay "
                                              "(see its gateway's log)")
        self.counts["accepted"] += 1
        return None

    def check_message(self, relay: str, message: Any) -> str | None:
        """:meth:`check` for a request or message with a ``signature`` field (hindrax_msgs/Signature)."""
        s = message.signature
        return self.check(relay, Signature(int(s.link_id), int(s.timestamp), bytes(s.mac)), signed_payload(message))

    def _refuse(self, kind: str, why: str) -> str:
        self.counts[kind] += 1
        return why
