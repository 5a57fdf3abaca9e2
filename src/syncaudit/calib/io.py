"""Reading what method B needs from a log: PointCloud2 scans and the static transforms.

Point fields are decoded through a structured numpy dtype built from the message's
`fields` list (zero-copy view of the data buffer), never point by point in Python.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from syncaudit.calib import se3
from syncaudit.errors import LogReadError, NoDataError
from syncaudit.logs import open_log

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
TFMESSAGE = "tf2_msgs/msg/TFMessage"
ODOMETRY = "nav_msgs/msg/Odometry"

_DATATYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
"""sensor_msgs/PointField datatype codes -> numpy type codes (without byte order)."""


@dataclass(frozen=True)
class Scan:
    """One LiDAR scan: its points (float32, metres, sensor frame) and when it was taken."""

    topic: str
    frame_id: str
    stamp_ns: int
    points_m: NDArray[np.float32]
    times_ns: NDArray[np.int64] | None = None
    """Per-point time relative to `stamp_ns` (None: the cloud has no time field)."""


@dataclass(frozen=True)
class StaticTransform:
    """One edge of the static transform tree: `parent_from_child`."""

    parent: str
    child: str
    parent_from_child: NDArray[np.float64]


def pointcloud2_dtype(fields: Iterable[Any], point_step: int, is_bigendian: bool) -> np.dtype[Any]:
    """Structured dtype of one point from PointField records (name, offset, datatype, count)."""
    order = ">" if is_bigendian else "<"
    names: list[str] = []
    formats: list[Any] = []
    offsets: list[int] = []
    for field in fields:
        name = str(field.name)
        if not name or name in names:
            continue  # unnamed padding or a duplicate name: not addressable, skip it
        code = _DATATYPES.get(int(field.datatype))
        if code is None:
            raise LogReadError(f"PointField {name!r} has unknown datatype {field.datatype}")
        count = max(1, int(field.count))
        fmt: Any = order + code if count == 1 else (order + code, (count,))
        size = np.dtype(fmt).itemsize
        if int(field.offset) + size > point_step:
            raise LogReadError(
                f"PointField {name!r} (offset {field.offset}, {size} bytes) "
                f"overruns point_step {point_step}"
            )
        names.append(name)
        formats.append(fmt)
        offsets.append(int(field.offset))
    return np.dtype(
        {"names": names, "formats": formats, "offsets": offsets, "itemsize": point_step}
    )


def decode_xyz(msg: Any, topic: str = "") -> NDArray[np.float32]:
    """(N, 3) float32 x/y/z of a PointCloud2, without NaN/inf points or all-zero returns."""
    return decode_xyz_times(msg, topic)[0]


_TIME_FIELDS: tuple[tuple[str, float, bool], ...] = (
    ("time", 1e9, False),
    ("t", 1.0, False),
    ("timestamp", 1e9, True),
    ("time_stamp", 1e9, True),
)
"""Per-point time fields drivers publish: (name, to-ns factor, absolute). Velodyne's
`time` (float s from the scan stamp), Ouster's `t` (uint32 ns from it), Hesai's and
nebula's `timestamp` / `time_stamp` (float s, absolute: the scan stamp is subtracted)."""


def decode_xyz_times(
    msg: Any, topic: str = "", stamp_ns: int = 0
) -> tuple[NDArray[np.float32], NDArray[np.int64] | None]:
    """x/y/z as `decode_xyz` and each kept point's time from the scan stamp (ns; None when
    the cloud has no time field)."""
    width, height = int(msg.width), int(msg.height)
    point_step, row_step = int(msg.point_step), int(msg.row_step)
    n = width * height
    if n == 0:
        return np.zeros((0, 3), dtype=np.float32), None
    if point_step <= 0 or row_step < width * point_step:
        raise LogReadError(f"{topic}: PointCloud2 point_step/row_step inconsistent with width")
    dtype = pointcloud2_dtype(msg.fields, point_step, bool(msg.is_bigendian))
    if not {"x", "y", "z"} <= set(dtype.names or ()):
        raise NoDataError(f"{topic}: PointCloud2 has no x/y/z fields")
    data = np.frombuffer(msg.data, dtype=np.uint8)
    if data.size < height * row_step:
        raise LogReadError(
            f"{topic}: PointCloud2 data is {data.size} bytes, expected {height * row_step}"
        )
    if row_step == width * point_step:
        points = np.frombuffer(data, dtype=dtype, count=n)
    else:  # rows padded: drop the padding (the only case that copies the buffer)
        rows = data[: height * row_step].reshape(height, row_step)[:, : width * point_step]
        points = np.ascontiguousarray(rows).reshape(-1).view(dtype)
    xyz = np.empty((n, 3), dtype=np.float32)
    for i, axis in enumerate(("x", "y", "z")):
        xyz[:, i] = points[axis]
    keep = np.isfinite(xyz).all(axis=1) & (np.abs(xyz).sum(axis=1) > 0.0)
    times = None
    names = set(dtype.names or ())
    for name, factor, absolute in _TIME_FIELDS:
        if name in names and np.asarray(points[name]).ndim == 1:
            raw_t = np.asarray(points[name], dtype=np.float64) * factor
            times = np.rint(raw_t - (stamp_ns if absolute else 0)).astype(np.int64)
            break
    if keep.all():
        return xyz, times
    return xyz[keep], None if times is None else times[keep]


def _stamp_ns(msg: Any, log_time_ns: int) -> int:
    """Header stamp in ns (the sensor's time); the log time when the stamp is unset."""
    stamp = msg.header.stamp
    ns = int(stamp.sec) * 1_000_000_000 + int(getattr(stamp, "nanosec", getattr(stamp, "nsec", 0)))
    return ns if ns > 0 else log_time_ns


def pointcloud_topics(path: Path) -> dict[str, int]:
    """PointCloud2 topics of the log with their message counts (0 where unknown)."""
    with open_log(path) as log:
        return {
            name: int(info.count or 0)
            for name, info in sorted(log.topics.items())
            if info.msgtype == POINTCLOUD2
        }


def iter_scans(path: Path, topics: Iterable[str]) -> Iterator[Scan]:
    """Decoded scans of `topics` in log order; NoDataError for a topic not in the log."""
    wanted = list(topics)
    with open_log(path) as log:
        for topic in wanted:
            info = log.topics.get(topic)
            if info is None:
                raise NoDataError(f"{path}: no topic {topic}")
            if info.msgtype != POINTCLOUD2:
                raise NoDataError(f"{path}: {topic} carries {info.msgtype}, not PointCloud2")
        for raw in log.messages(topics=wanted):
            try:
                msg: Any = log.deserialize(raw)
            except (ValueError, IndexError, KeyError) as exc:
                raise LogReadError(
                    f"{path}: cannot decode a PointCloud2 on {raw.topic}: {exc}"
                ) from exc
            yield Scan(
                topic=raw.topic,
                frame_id=str(msg.header.frame_id).lstrip("/"),
                stamp_ns=(stamp := _stamp_ns(msg, raw.log_time_ns)),
                points_m=(decoded := decode_xyz_times(msg, raw.topic, stamp))[0],
                times_ns=decoded[1],
            )


def read_static_transforms(path: Path, tf_topic: str) -> list[StaticTransform]:
    """Every transform on `tf_topic` (the last one wins per child); [] when the topic is absent."""
    edges: dict[str, StaticTransform] = {}
    with open_log(path) as log:
        info = log.topics.get(tf_topic)
        if info is None:
            return []
        for raw in log.messages(topics=[tf_topic]):
            msg: Any = log.deserialize(raw)
            for tr in msg.transforms:
                t = tr.transform.translation
                q = tr.transform.rotation
                try:
                    rot = se3.quaternion_to_matrix(float(q.x), float(q.y), float(q.z), float(q.w))
                except ValueError:
                    continue  # a zero quaternion carries no transform
                child = str(tr.child_frame_id).lstrip("/")
                edges[child] = StaticTransform(
                    parent=str(tr.header.frame_id).lstrip("/"),
                    child=child,
                    parent_from_child=se3.make_transform(rot, (float(t.x), float(t.y), float(t.z))),
                )
    return list(edges.values())


@dataclass(frozen=True)
class Odometry:
    """The vehicle's odometry: `odom_from_base` poses (N, 4, 4) at sorted stamps, and where
    they came from."""

    source: str
    stamps_ns: NDArray[np.int64]
    poses: NDArray[np.float64]

    def at(self, stamp_ns: int) -> NDArray[np.float64]:
        """The pose of the sample nearest in time to `stamp_ns`."""
        i = int(np.clip(np.searchsorted(self.stamps_ns, stamp_ns), 1, self.stamps_ns.size - 1))
        if abs(int(self.stamps_ns[i - 1]) - stamp_ns) <= abs(int(self.stamps_ns[i]) - stamp_ns):
            i -= 1
        return np.asarray(self.poses[i])


def _pose_matrix(position: Any, orientation: Any) -> NDArray[np.float64] | None:
    q = orientation
    try:
        rot = se3.quaternion_to_matrix(float(q.x), float(q.y), float(q.z), float(q.w))
    except ValueError:
        return None
    return se3.make_transform(rot, (float(position.x), float(position.y), float(position.z)))


def read_odometry(path: Path, base_frame: str) -> Odometry | None:
    """The vehicle's odometry from the log, or None when it has none.

    Prefers a nav_msgs/Odometry topic whose child frame is `base_frame` (the first such
    topic by name), else /tf transforms whose child is `base_frame` (e.g. odom ->
    base_link). Only these small messages are decoded.
    """
    with open_log(path) as log:
        odom_topics = sorted(t for t, i in log.topics.items() if i.msgtype == ODOMETRY)
        tf_topics = [t for t, i in log.topics.items() if t == "/tf" and i.msgtype == TFMESSAGE]
        for topic in odom_topics:
            stamps: list[int] = []
            poses: list[NDArray[np.float64]] = []
            for raw in log.messages(topics=[topic]):
                msg: Any = log.deserialize(raw)
                if str(msg.child_frame_id).lstrip("/") != base_frame:
                    break
                pose = _pose_matrix(msg.pose.pose.position, msg.pose.pose.orientation)
                if pose is not None:
                    stamps.append(_stamp_ns(msg, raw.log_time_ns))
                    poses.append(pose)
            if len(stamps) >= 2:
                return _odometry(topic, stamps, poses)
        for topic in tf_topics:
            stamps, poses = [], []
            for raw in log.messages(topics=[topic]):
                msg = log.deserialize(raw)
                for tr in msg.transforms:
                    if str(tr.child_frame_id).lstrip("/") != base_frame:
                        continue
                    pose = _pose_matrix(tr.transform.translation, tr.transform.rotation)
                    if pose is not None:
                        stamps.append(_stamp_ns(tr, raw.log_time_ns))
                        poses.append(pose)
            if len(stamps) >= 2:
                return _odometry(f"{topic} -> {base_frame}", stamps, poses)
    return None


def _odometry(source: str, stamps: list[int], poses: list[NDArray[np.float64]]) -> Odometry:
    order = np.argsort(np.asarray(stamps, dtype=np.int64), kind="stable")
    return Odometry(
        source=source,
        stamps_ns=np.asarray(stamps, dtype=np.int64)[order],
        poses=np.stack(poses)[order],
    )
