"""Which camera each extracted camera row belongs to, where cameras share a topic.

Drivers publish per-frame camera messages one topic per camera (the ROS 2
spinnaker_camera_driver, Autoware's `/sensing/camera/cameraN/...`) or one topic for several
cameras, each message naming its camera only in `header.frame_id` (a driver node serving a
multi-camera board). A row of a topic one camera owns goes to that camera. A row of a
shared topic goes to the camera its message names: the `camera` field of the syncaudit
types (the rig's camera name), else its `header.frame_id` (the rig camera's `frame_id`; a
leading "/", which ROS 1 tf allowed and tf2 strips, is ignored).

A row that names no camera cannot be told apart: image and exposure rows are then left out
(each would be a frame of every camera) with one warning per topic, and the cameras that
end without frames say why they are not judged. A trigger that names no camera (a
`builtin_interfaces/Time` has nothing to name one with) is offered to every camera of the
topic: one pulse often triggers several cameras at once (TIER IV's sensor_trigger drives
the FSYNC of a GMSL deserializer), and pairing by time picks each frame's own trigger.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Container
from dataclasses import dataclass, field
from typing import Any

from syncaudit.camera.extract import CameraTableBuilder
from syncaudit.camera.rowstore import DamagedRow, RowStore
from syncaudit.errors import LogReadError
from syncaudit.rig import CameraConfig

KINDS = ("image", "exposure", "trigger")
"""What a camera topic holds, as `collect.extract` labels its items."""


def camera_topics(cam: CameraConfig, recorded: Container[str]) -> list[tuple[str, str]]:
    """(kind, topic) of each recorded topic a camera reads, as the audit reads them.

    Frames come from the image headers, or from CameraInfo where no image was recorded.
    """
    frame_topic = cam.image_topic if cam.image_topic in recorded else cam.info_topic
    wanted = (
        ("image", frame_topic),
        ("exposure", cam.exposure_topic),
        ("trigger", cam.trigger_topic),
    )
    return [(kind, topic) for kind, topic in wanted if topic is not None and topic in recorded]


@dataclass(frozen=True, slots=True)
class SharedTopicCount:
    """What became of the messages of one topic several cameras share."""

    kind: str
    topic: str
    cameras: tuple[str, ...]
    """The cameras reading the topic (rig order)."""
    per_camera: dict[str, int]
    """Messages given to each camera."""
    frame_ids: dict[str, int]
    """Readable messages by their header.frame_id ("" for none)."""
    unnamed: int
    """Messages naming no camera (triggers among them went to every camera)."""
    unknown: dict[str, int]
    """Messages naming a frame or camera no camera of the topic has, by what they name."""
    damaged: int


def _rows_of(builder: CameraTableBuilder, kind: str) -> RowStore:
    rows: RowStore = {
        "image": builder.images,
        "exposure": builder.exposures,
        "trigger": builder.triggers,
    }[kind]
    return rows


def _identity(kind: str, row: tuple[Any, ...]) -> tuple[str, str]:
    """(camera name the row's message gives, its header.frame_id); "" where it gives none."""
    if kind == "image":
        return "", str(row[3])
    return str(row[0] or ""), str(row[-1] or "")


def _named_camera(
    builders: list[CameraTableBuilder], name: str, frame: str
) -> CameraTableBuilder | None:
    """The builder of the camera a message names: by `camera` field, else by frame_id."""
    if name:
        target = next((b for b in builders if b.camera.name == name), None)
        if target is not None:
            return target
    if not frame:
        return None
    bare = frame.lstrip("/")
    return next((b for b in builders if (b.camera.frame_id or "").lstrip("/") == bare), None)


@dataclass(slots=True)
class _SharedTopic:
    """One topic several cameras read, and what became of its rows."""

    kind: str
    topic: str
    builders: list[CameraTableBuilder]
    routed: Counter[str] = field(default_factory=Counter)
    """Rows given to each camera (by name)."""
    unnamed: int = 0
    unknown: Counter[str] = field(default_factory=Counter)
    """Rows naming a frame or camera the rig does not have there, by what they name."""
    damaged: list[DamagedRow] = field(default_factory=list)
    frame_ids: Counter[str] = field(default_factory=Counter)
    """Readable rows by the header.frame_id they carry ("" for none)."""

    def route(self, row: tuple[Any, ...] | DamagedRow) -> None:
        if isinstance(row, DamagedRow):
            self.damaged.append(row)
            return
        name, frame = _identity(self.kind, row)
        self.frame_ids[frame] += 1
        target = _named_camera(self.builders, name, frame)
        if target is not None:
            _rows_of(target, self.kind).append(row)
            self.routed[target.camera.name] += 1
        elif name or frame:
            self.unknown[f"frame_id {frame!r}" if frame else f"camera field {name!r}"] += 1
        elif self.kind == "trigger":
            for builder in self.builders:
                _rows_of(builder, self.kind).append(row)
            self.unnamed += 1
        else:
            self.unnamed += 1

    def finish(self) -> list[str]:
        """Warnings for what could not be routed; notes on the cameras it left without rows.

        Raises LogReadError where every message of the topic is damaged.
        """
        names = ", ".join(b.camera.name for b in self.builders)
        what = f"{self.kind} topic {self.topic} (shared by cameras {names})"
        readable = sum(self.routed.values()) + self.unnamed + sum(self.unknown.values())
        warnings = []
        if self.damaged:
            first = self.damaged[0]
            where = f"first at log time {first.log_time_ns / 1e9:.9f} s: {first.reason}"
            if not readable:
                raise LogReadError(
                    f"all {len(self.damaged)} messages on {what} are damaged ({where})"
                )
            warnings.append(f"{len(self.damaged)} damaged messages skipped on {what} ({where})")
        if self.unnamed and self.kind == "trigger":
            warnings.append(
                f"{what}: {self.unnamed} triggers name no camera (no camera field, no "
                "header.frame_id); each was offered to every camera of the topic and paired "
                "by time"
            )
        elif self.unnamed:
            warnings.append(
                f"{what}: {self.unnamed} messages carry no header.frame_id (nor camera field) "
                "to tell the cameras apart and were not used; set each camera's frame_id in "
                "the rig to the header.frame_id its messages carry"
            )
        if self.unknown:
            claimed = ", ".join(f"{b.camera.name} {b.camera.frame_id!r}" for b in self.builders)
            for label, count in sorted(self.unknown.items()):
                warnings.append(
                    f"{what}: {count} messages with {label} name no camera of the "
                    f"rig there (the rig's frame_ids: {claimed}); they were not used"
                )
        for builder in self.builders:
            if not readable or self.routed[builder.camera.name] or self.kind == "trigger":
                continue  # an empty topic says nothing of the cameras sharing it
            others = ", ".join(b.camera.name for b in self.builders if b is not builder)
            if builder.camera.frame_id is None:
                why = "the rig gives the camera no frame_id to find its messages by"
            elif self.unnamed and not self.unknown:
                why = "its messages carry no header.frame_id to tell the cameras apart"
            else:
                why = f"no message carries its frame_id {builder.camera.frame_id!r}"
            builder.shared_topic_notes.append(
                f"no {self.kind} messages for it on {self.topic}, which it shares with {others}: {why}"
            )
        return warnings


@dataclass(slots=True)
class CameraRouter:
    """Sends each camera item of the audit's pass over the log to its camera's builder."""

    builders: dict[str, CameraTableBuilder] = field(default_factory=dict)
    """Camera name -> its builder."""
    _owners: dict[tuple[str, str], list[CameraTableBuilder]] = field(default_factory=dict)
    _single: dict[tuple[str, str], RowStore] = field(default_factory=dict)
    _shared: dict[tuple[str, str], _SharedTopic] = field(default_factory=dict)

    @classmethod
    def for_cameras(cls, cameras: list[CameraConfig], recorded: Container[str]) -> CameraRouter:
        """A router with one builder per camera, reading its `camera_topics`."""
        router = cls()
        for cam in cameras:
            builder = CameraTableBuilder(cam)
            router.builders.setdefault(cam.name, builder)
            for kind, topic in camera_topics(cam, recorded):
                router.add(kind, topic, builder)
        return router

    def add(self, kind: str, topic: str, builder: CameraTableBuilder) -> None:
        """Let `builder`'s camera read `topic` for rows of `kind` (image/exposure/trigger)."""
        self.builders.setdefault(builder.camera.name, builder)
        owners = self._owners.setdefault((kind, topic), [])
        if builder not in owners:
            owners.append(builder)
        readers = tuple(o.camera.name for o in owners)
        for owner in owners:
            owner.topic_readers[kind] = (topic, readers)
        key = (kind, topic)
        if len(owners) == 1:
            self._single[key] = _rows_of(builder, kind)
        else:
            self._single.pop(key, None)
            self._shared[key] = _SharedTopic(kind, topic, owners)

    def topics(self, kind: str) -> dict[str, list[CameraTableBuilder]]:
        """Each topic of `kind` and the cameras reading it."""
        return {t: owners for (k, t), owners in self._owners.items() if k == kind}

    def feed(self, kind: str, topic: str, payload: Any) -> None:
        """One extracted row, to the camera (or cameras) it belongs to."""
        rows = self._single.get((kind, topic))
        if rows is not None:
            rows.append(payload)
        else:
            self._shared[(kind, topic)].route(payload)

    def shared_counts(self) -> list[SharedTopicCount]:
        """Per topic several cameras read, where its messages went (by kind, then topic)."""
        return [
            SharedTopicCount(
                kind=s.kind,
                topic=s.topic,
                cameras=tuple(b.camera.name for b in s.builders),
                per_camera={b.camera.name: s.routed[b.camera.name] for b in s.builders},
                frame_ids=dict(sorted(s.frame_ids.items())),
                unnamed=s.unnamed,
                unknown=dict(sorted(s.unknown.items())),
                damaged=len(s.damaged),
            )
            for _, s in sorted(
                self._shared.items(), key=lambda kv: (KINDS.index(kv[0][0]), kv[0][1])
            )
        ]

    def finish(self) -> list[str]:
        """Warnings about shared topics (rows no camera could be given), once the pass ended.

        Raises LogReadError where every message of a shared topic is damaged.
        """
        return [w for shared in self._shared.values() for w in shared.finish()]
