"""metadata.yaml as rosbag2 (version 9) writes it: per MCAP file and per topic what it holds, and
the bag's ``custom_data``; written atomically, so a bag directory always has a whole one. Shared by
the writer (at the start, every split and the end) and recovery (rebuilt from the MCAP files)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import yaml

from .schema import typestore


@dataclass
class FileStats:
    path: str  # relative to the bag directory
    start: int = 2**63 - 1
    end: int = 0
    count: int = 0

    def rosbag2(self) -> dict:
        return {
            "path": self.path,
            "starting_time": {"nanoseconds_since_epoch": self.start if self.count else 0},
            "duration": {"nanoseconds": max(0, self.end - self.start)},
            "message_count": self.count,
        }


@dataclass
class TopicStats:
    msgtype: str
    qos: str
    count: int = 0


def rosbag2_metadata(files: list[FileStats], topics: dict, custom: dict[str, str]) -> dict:
    """metadata.yaml's content as rosbag2 (version 9) writes it, for the given files; ``topics``
    maps a topic to an object with ``msgtype``, ``qos`` (the offered QoS as YAML text) and ``count``."""
    store = typestore()
    start = min((f.start for f in files if f.count), default=0)
    end = max((f.end for f in files if f.count), default=start)
    return {
        "rosbag2_bagfile_information": {
            "version": 9,
            "storage_identifier": "mcap",
            "relative_file_paths": [f.path for f in files],
            "duration": {"nanoseconds": end - start},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": sum(f.count for f in files),
            "topics_with_message_count": [
                {
                    "topic_metadata": {
                        "name": name,
                        "type": t.msgtype,
                        "serialization_format": "cdr",
                        "offered_qos_profiles": yaml.safe_load(t.qos) or [],
                        "type_description_hash": store.hash_rihs01(t.msgtype) if t.msgtype in store.fielddefs else "",
                    },
                    "message_count": t.count,
                }
                for name, t in topics.items()
            ],
            # Chunk compression is the storage's own (as rosbag2's MCAP plugin with a zstd preset):
            # rosbag2's file/message compression is not used.
            "compression_format": "",
            "compression_mode": "",
            "files": [f.rosbag2() for f in files],
            "custom_data": custom or None,
            "ros_distro": "jazzy",
        }
    }


def write_metadata(path: Path, metadata: dict) -> None:
    """Writes ``path``/metadata.yaml atomically (a temporary file fsynced, then renamed)."""
    target = path / "metadata.yaml"
    tmp = path / ".metadata.yaml.tmp"
    with open(tmp, "w") as f:
        yaml.safe_dump(metadata, f, default_flow_style=False, sort_keys=True)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, target)
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
