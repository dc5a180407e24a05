"""``hindrax decode <device> FILE``: run a serial driver's own parser over a capture, print JSON records.

Devices:

- ``dvl75``: a text capture of the DVL-75 serial stream (docs/devices.md §1.2-§1.3). Decoded with
  :class:`hindrax_drivers.dvl75.stream.DvlStreamDecoder`, the path the DVL node uses, fed one line
  (LF-terminated segment) at a time so every problem is reported with its line number. A last line
  without LF is decoded as a complete line.
- ``ping1d``: a raw binary capture of the Ping1D stream, either direction (docs/devices.md §2.2-§2.4).
  Decoded with :class:`hindrax_drivers.ping1d.stream.Ping1dStreamDecoder`, the path the Ping node uses;
  problems are reported with their byte offset.

Output: one JSON object per decoded record on stdout, ``{"type": <record class>, "line": n, ...}`` (DVL)
or ``{"type": <payload class>, "message_id": id, "offset": n, "src_device_id": s, "dst_device_id": d,
...}`` (Ping), followed by the record's fields with the protocol module's names and SI units (s, m,
m/s, rad, %, V, degC; profile samples as a list of integers). Every line or frame that does not parse is
reported on stderr with its position, kind (bad_checksum, truncated, malformed, unknown_sentence /
unknown_message, garbage_bytes) and reason, then one summary line with the counts.
Exit status: 0 if at least one record was decoded, 1 otherwise (or when FILE cannot be read).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from collections import Counter
from typing import Any, Dict

DEVICES = ("dvl75", "ping1d")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments: ``device`` (dvl75 | ping1d) and ``file`` (``-`` reads stdin)."""
    parser.add_argument("device", choices=DEVICES, help="which driver's parser to run")
    parser.add_argument("file", help="capture: text lines for dvl75, raw bytes for ping1d ('-' = stdin)")


def _jsonable(value: Any) -> Any:
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if isinstance(value, (tuple, list)):
        return [_jsonable(v) for v in value]
    if hasattr(value, "item"):  # numpy scalar
        return value.item()
    return value


def _fields(record: Any) -> Dict[str, Any]:
    return {f.name: _jsonable(getattr(record, f.name)) for f in dataclasses.fields(record)}


def _summary(unit: str, by_type: Counter, counts: Dict[str, int], err) -> int:
    """Write the summary line on ``err``; returns the exit status (1 when nothing was decoded)."""
    n_records = sum(by_type.values())
    failed = {k: v for k, v in counts.items() if v and k != "garbage_bytes"}
    types = ", ".join(f"{k} {v}" for k, v in sorted(by_type.items())) or "none"
    parts = [f"decode: {n_records} record(s) ({types})"]
    n_failed = sum(failed.values())
    detail = ", ".join(f"{k} {v}" for k, v in sorted(failed.items()))
    parts.append(f"{n_failed} {unit}(s) did not parse" + (f" ({detail})" if detail else ""))
    parts.append(f"{counts.get('garbage_bytes', 0)} garbage byte(s) discarded")
    err.write("; ".join(parts) + "\n")
    return 0 if n_records else 1


def _decode_dvl(data: bytes, out, err) -> int:
    from hindrax_drivers.dvl75.stream import DvlStreamDecoder

    decoder = DvlStreamDecoder(keep_errors=True)
    pieces = data.split(b"\n")
    if pieces and pieces[-1] == b"":
        pieces.pop()
    by_type: Counter = Counter()
    reported = 0
    for number, piece in enumerate(pieces, start=1):
        for record in decoder.feed(piece + b"\n"):
            name = type(record).__name__
            by_type[name] += 1
            out.write(json.dumps({"type": name, "line": number, **_fields(record)}) + "\n")
        for e in decoder.errors[reported:]:
            err.write(f"dvl75 line {e.line}: {e.kind}: {e.reason}\n")
        reported = len(decoder.errors)
    return _summary("line", by_type, decoder.counts, err)


def _decode_ping(data: bytes, out, err) -> int:
    from hindrax_drivers.ping1d.stream import Ping1dStreamDecoder

    decoder = Ping1dStreamDecoder(keep_errors=True)
    items = decoder.feed(data)
    decoder.finish()
    by_type: Counter = Counter()
    for item in items:
        name = type(item.payload).__name__
        by_type[name] += 1
        m = item.message
        out.write(json.dumps({"type": name, "message_id": m.message_id, "offset": item.offset,
                              "src_device_id": m.src_device_id, "dst_device_id": m.dst_device_id,
                              **_fields(item.payload)}) + "\n")
    for e in sorted(decoder.errors, key=lambda e: e.offset):
        err.write(f"ping1d offset {e.offset}: {e.kind}: {e.reason}\n")
    return _summary("frame", by_type, decoder.counts, err)


def run(args: argparse.Namespace) -> int:
    """Decode ``args.file`` with the parser of ``args.device``; see the module docstring for the output."""
    try:
        if args.file == "-":
            data = sys.stdin.buffer.read()
        else:
            with open(args.file, "rb") as f:
                data = f.read()
    except OSError as exc:
        print(f"decode: cannot read {args.file}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    if args.device == "dvl75":
        return _decode_dvl(data, sys.stdout, sys.stderr)
    return _decode_ping(data, sys.stdout, sys.stderr)
