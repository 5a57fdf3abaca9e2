"""A ROS 2 bag folder split into several files, as rosbag2 writes it after a split.

rosbags' `Writer` writes one storage file per bag; rosbag2's recorder splits a long
recording (`--max-bag-size`, `--max-bag-duration`) into files that each declare their
channels anew, under one `metadata.yaml` listing every file. `SplitBagWriter` builds that
layout from one rosbags `Writer` per part, for tests and benchmarks of split bags.
"""

from __future__ import annotations

import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

if TYPE_CHECKING:
    from rosbags.interfaces import Connection
    from rosbags.rosbag2 import Writer
    from rosbags.typesys.store import Typestore

METADATA = "metadata.yaml"
INFO_KEY = "rosbag2_bagfile_information"


def merged_metadata(parts: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """One bag's `rosbag2_bagfile_information` from its parts' (in file order).

    Files, message counts (per topic and in total), start and duration span every part;
    everything else (version, storage, topics' metadata) is the first part's.
    """
    info = dict(parts[0])
    info["files"] = [f for p in parts for f in p["files"]]
    info["relative_file_paths"] = [f["path"] for f in info["files"]]
    info["message_count"] = sum(p["message_count"] for p in parts)
    counts: dict[str, int] = {}
    for p in parts:
        for t in p["topics_with_message_count"]:
            name = t["topic_metadata"]["name"]
            counts[name] = counts.get(name, 0) + t["message_count"]
    info["topics_with_message_count"] = [
        {**t, "message_count": counts[t["topic_metadata"]["name"]]}
        for t in parts[0]["topics_with_message_count"]
    ]
    first = min(p["starting_time"]["nanoseconds_since_epoch"] for p in parts)
    last = max(
        p["starting_time"]["nanoseconds_since_epoch"] + p["duration"]["nanoseconds"] for p in parts
    )
    info["starting_time"] = {"nanoseconds_since_epoch": first}
    info["duration"] = {"nanoseconds": last - first}
    return info


class SplitBagWriter:
    """Writes a bag folder part by part: `start_part`, `write`..., then `close`.

    Each part is written by its own rosbags `Writer` into a scratch folder beside the bag;
    its storage file moves into the bag as `<stem>_<part>.<ext>` (`stem`: the folder's name
    unless given, e.g. the final name of a folder written under a temporary one).
    """

    def __init__(
        self, folder: Path, typestore: Typestore, *, storage: str = "mcap", stem: str | None = None
    ) -> None:
        self.folder = folder
        self.stem = folder.name if stem is None else stem
        self.typestore = typestore
        self.storage = storage
        self.files: list[Path] = []
        self._infos: list[dict[str, Any]] = []
        self._writer: Writer | None = None
        self._conns: dict[str, Connection] = {}
        folder.mkdir()

    def _scratch(self) -> Path:
        return self.folder.parent / f".{self.folder.name}.part{len(self._infos)}.tmp"

    def start_part(self, topics: Sequence[tuple[str, str]]) -> None:
        """Open the next part, declaring (topic, message type) in this order."""
        from rosbags.rosbag2 import StoragePlugin, Writer

        self.finish_part()
        plugin = StoragePlugin.MCAP if self.storage == "mcap" else StoragePlugin.SQLITE3
        writer = Writer(self._scratch(), version=8, storage_plugin=plugin)
        writer.open()
        self._conns = {
            topic: writer.add_connection(topic, msgtype, typestore=self.typestore)
            for topic, msgtype in topics
        }
        self._writer = writer

    def write(self, topic: str, log_time_ns: int, data: bytes) -> None:
        """One serialized message into the open part."""
        assert self._writer is not None, "start_part first"
        self._writer.write(self._conns[topic], log_time_ns, data)

    def finish_part(self) -> None:
        """Close the open part (if any) and move its file into the bag."""
        if self._writer is None:
            return
        self._writer.close()
        self._writer = None
        scratch = self._scratch()
        info = yaml.safe_load((scratch / METADATA).read_text())[INFO_KEY]
        (entry,) = info["files"]
        target = self.folder / f"{self.stem}_{len(self._infos)}{Path(entry['path']).suffix}"
        shutil.move(scratch / entry["path"], target)
        entry["path"] = target.name
        info["relative_file_paths"] = [target.name]
        shutil.rmtree(scratch)
        self.files.append(target)
        self._infos.append(info)

    def close(self) -> None:
        """Finish the last part and write the bag's one `metadata.yaml`."""
        self.finish_part()
        text = yaml.safe_dump({INFO_KEY: merged_metadata(self._infos)}, sort_keys=False)
        (self.folder / METADATA).write_text(text)
