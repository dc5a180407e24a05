"""rosbag2 bag metadata (``metadata.yaml``, version 9, Jazzy) as typed objects, written and read.

Layout (rosbag2_storage ``yaml.hpp`` / ``metadata_io.cpp``, Jazzy; docs/architecture.md §11.6)::

    rosbag2_bagfile_information:
      version: 9
      storage_identifier: mcap
      duration: {nanoseconds: N}                 # last - first message log time
      starting_time: {nanoseconds_since_epoch: T}
      message_count: M
      topics_with_message_count:
      - topic_metadata: {name, type: pkg/msg/Type, serialization_format: cdr,
                         offered_qos_profiles: [ ... ],     # a YAML list from version 9 on
                         type_description_hash: RIHS01_...}
        message_count: m
      compression_format: ""                     # MCAP chunk compression is internal to the files
      compression_mode: ""
      relative_file_paths: [<bag>_0.mcap, ...]
      files: [{path, starting_time: {nanoseconds_since_epoch}, duration: {nanoseconds}, message_count}]
      custom_data: {}
      ros_distro: jazzy

The same mapping (without the ``rosbag2_bagfile_information`` key) is what rosbag2's MCAP plugin
serialises into each file's ``rosbag2`` metadata record (key ``serialized_metadata``).

Pure (PyYAML only). Errors: :class:`MetadataError` (a ``ValueError``) naming the file and the problem."""
from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import yaml

from .qos import profiles_from_yaml

METADATA_FILENAME = "metadata.yaml"
METADATA_VERSION = 9
ROS_DISTRO = "jazzy"
STORAGE_IDENTIFIER = "mcap"


class MetadataError(ValueError):
    """metadata.yaml missing, unreadable or not in the rosbag2 layout."""


@dataclass
class TopicInfo:
    """One recorded topic: name, ``pkg/msg/Type``, QoS profiles of its publishers, RIHS01 hash, count."""

    name: str
    type: str
    offered_qos_profiles: list[dict] = field(default_factory=list)
    type_description_hash: str = ""
    message_count: int = 0
    serialization_format: str = "cdr"

    def to_yaml_obj(self) -> dict:
        return {
            "topic_metadata": {
                "name": self.name,
                "type": self.type,
                "serialization_format": self.serialization_format,
                "offered_qos_profiles": [dict(p) for p in self.offered_qos_profiles],
                "type_description_hash": self.type_description_hash,
            },
            "message_count": int(self.message_count),
        }


@dataclass
class FileInfo:
    """One storage file of the bag: path relative to the bag directory, first log time, span, count."""

    path: str
    starting_time_ns: int = 0
    duration_ns: int = 0
    message_count: int = 0

    def to_yaml_obj(self) -> dict:
        return {"path": self.path, "starting_time": {"nanoseconds_since_epoch": int(self.starting_time_ns)},
                "duration": {"nanoseconds": int(self.duration_ns)}, "message_count": int(self.message_count)}


@dataclass
class BagMetadata:
    """The whole bag: files in order and topics with counts; times in ns since the epoch (log time)."""

    files: list[FileInfo] = field(default_factory=list)
    topics: list[TopicInfo] = field(default_factory=list)
    version: int = METADATA_VERSION
    storage_identifier: str = STORAGE_IDENTIFIER
    ros_distro: str = ROS_DISTRO
    custom_data: dict[str, str] = field(default_factory=dict)

    @property
    def message_count(self) -> int:
        return sum(f.message_count for f in self.files)

    @property
    def starting_time_ns(self) -> int:
        times = [f.starting_time_ns for f in self.files if f.message_count]
        return min(times) if times else 0

    @property
    def duration_ns(self) -> int:
        ends = [f.starting_time_ns + f.duration_ns for f in self.files if f.message_count]
        return max(0, max(ends) - self.starting_time_ns) if ends else 0

    @property
    def relative_file_paths(self) -> list[str]:
        return [f.path for f in self.files]

    def topic(self, name: str) -> TopicInfo:
        for t in self.topics:
            if t.name == name:
                return t
        raise KeyError(name)

    def to_yaml_obj(self) -> dict:
        """The mapping under ``rosbag2_bagfile_information`` (also the ``serialized_metadata`` content)."""
        return {
            "version": self.version,
            "storage_identifier": self.storage_identifier,
            "duration": {"nanoseconds": int(self.duration_ns)},
            "starting_time": {"nanoseconds_since_epoch": int(self.starting_time_ns)},
            "message_count": int(self.message_count),
            "topics_with_message_count": [t.to_yaml_obj() for t in self.topics],
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": self.relative_file_paths,
            "files": [f.to_yaml_obj() for f in self.files],
            "custom_data": dict(self.custom_data),
            "ros_distro": self.ros_distro,
        }

    def serialized(self) -> str:
        """YAML text of :meth:`to_yaml_obj` (the ``rosbag2`` MCAP metadata record value)."""
        return _dump(self.to_yaml_obj())

    def to_yaml(self) -> str:
        """Full metadata.yaml text."""
        return _dump({"rosbag2_bagfile_information": self.to_yaml_obj()})


_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)  # libyaml when available (10x faster)


def _dump(obj: Any) -> str:
    return yaml.dump(obj, Dumper=_DUMPER, sort_keys=False, default_flow_style=False, width=1000)


def write_metadata(bag_dir: str | Path, metadata: BagMetadata, fsync: bool = True) -> Path:
    """Write ``bag_dir/metadata.yaml`` atomically (temp file + rename, fsync'd). Returns its path."""
    bag_dir = Path(bag_dir)
    path = bag_dir / METADATA_FILENAME
    tmp = bag_dir / (METADATA_FILENAME + ".tmp")
    with open(tmp, "w") as f:
        f.write(metadata.to_yaml())
        f.flush()
        if fsync:
            os.fsync(f.fileno())
    os.replace(tmp, path)
    if fsync:
        _fsync_dir(bag_dir)
    return path


def _fsync_dir(path: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def metadata_from_mapping(info: Mapping[str, Any], source: str = "metadata") -> BagMetadata:
    """Build a :class:`BagMetadata` from the ``rosbag2_bagfile_information`` mapping (versions 5-9)."""
    try:
        version = int(info["version"])
        files = [FileInfo(str(f["path"]), int(f["starting_time"]["nanoseconds_since_epoch"]),
                          int(f["duration"]["nanoseconds"]), int(f["message_count"]))
                 for f in (info.get("files") or [])]
        if not files:  # versions < 5: one entry per relative path, no per-file counts
            files = [FileInfo(str(p)) for p in info.get("relative_file_paths") or []]
        topics = []
        for t in info.get("topics_with_message_count") or []:
            tm = t["topic_metadata"]
            qos = tm.get("offered_qos_profiles", [])
            if isinstance(qos, str):
                qos = profiles_from_yaml(qos)
            topics.append(TopicInfo(str(tm["name"]), str(tm["type"]), list(qos or []),
                                    str(tm.get("type_description_hash", "") or ""), int(t["message_count"]),
                                    str(tm.get("serialization_format", "cdr"))))
    except (KeyError, TypeError, ValueError) as exc:
        raise MetadataError(f"{source}: not rosbag2 bag metadata ({type(exc).__name__}: {exc})") from exc
    return BagMetadata(files=files, topics=topics, version=version,
                       storage_identifier=str(info.get("storage_identifier", STORAGE_IDENTIFIER)),
                       ros_distro=str(info.get("ros_distro", "") or ""),
                       custom_data=dict(info.get("custom_data") or {}))


def read_metadata(bag_dir: str | Path) -> BagMetadata:
    """Read ``bag_dir/metadata.yaml``. Raises :class:`MetadataError` (missing, bad YAML, wrong layout)."""
    path = Path(bag_dir) / METADATA_FILENAME
    try:
        doc = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise MetadataError(f"{path}: cannot read ({exc.strerror})") from exc
    except yaml.YAMLError as exc:
        raise MetadataError(f"{path}: invalid YAML ({str(exc).splitlines()[0]})") from exc
    if not isinstance(doc, Mapping) or "rosbag2_bagfile_information" not in doc:
        raise MetadataError(f"{path}: no rosbag2_bagfile_information mapping")
    return metadata_from_mapping(doc["rosbag2_bagfile_information"], str(path))
