"""Writing logs: one `open_writer` for MCAP, ROS 2 (sqlite3) bags and ROS 1 bags.

The writers take already-serialized bytes (`write`) or message objects of the writer's
typestore (`write_msg`). Types come from the same registry the readers use
(`syncaudit.logs.typesys.TypeRegistry`: the project's `schemas/` plus ROS defaults), so
everything written here is readable by `syncaudit.logs.open_log`, and every output carries
its own message definitions.

Outputs follow `syncaudit.writers.outputs`: the log is written to a hidden temporary path
beside the target and moved into place by a successful `close()` (or, when the caller
passes an `OutputSet`, by that set's commit together with the run's other outputs). An
error (or `abort()`) removes the temporary output and leaves the target untouched. An
existing target is never replaced unless `overwrite=True`, and a folder that is not a bag
this tool wrote is never replaced.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from abc import ABC, abstractmethod
from pathlib import Path
from types import TracebackType
from typing import Any, BinaryIO, Literal

import numpy as np
from mcap.writer import CompressionType
from mcap.writer import Writer as McapRawWriter
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability
from rosbags.interfaces import QosTime as RosbagsQosTime
from rosbags.rosbag1 import Writer as Rosbag1Writer
from rosbags.rosbag2 import Writer as Rosbag2Writer
from rosbags.typesys import Stores, get_typestore

from syncaudit.errors import ConfigError, UnknownTypeError
from syncaudit.logs.typesys import TypeRegistry, normalise_type_name
from syncaudit.writers.outputs import OutputSet
from syncaudit.writers.provenance import BAG2_KEY, WRITTEN_BY, mark_bag1

LogFormat = Literal["mcap", "mcap-ros1", "db3", "bag"]
"""'mcap': MCAP with ROS 2 CDR messages and ros2msg schemas (the default);
'mcap-ros1': MCAP with ROS 1 messages and ros1msg schemas; 'db3': ROS 2 bag directory with
sqlite3 storage; 'bag': ROS 1 bag."""

FORMATS: tuple[LogFormat, ...] = ("mcap", "mcap-ros1", "db3", "bag")

MCAP_CHUNK_BYTES = 4 * 1024 * 1024
"""Uncompressed MCAP chunk size: big enough for zstd to compress well, small enough for
readers to seek by time without decompressing much."""

_NS_PER_S = 1_000_000_000
_MAX_TIME_NS = 2**63 - 1


_SUFFIX_FORMATS: dict[str, tuple[LogFormat, ...]] = {
    ".mcap": ("mcap", "mcap-ros1"),
    ".bag": ("bag",),
    ".db3": ("db3",),
}


def infer_format(path: Path, fmt: LogFormat | None = None) -> LogFormat:
    """Format of an output log: `fmt` if given, else from the suffix (.mcap, .bag, .db3/none).

    Raises:
        ConfigError: the suffix is none of those, or it contradicts `fmt` (a `.mcap` name
            for a ROS 2 bag folder would make `x.mcap/x.mcap.db3`).
    """
    suffix = path.suffix.lower()
    allowed = _SUFFIX_FORMATS.get(suffix)
    if fmt is not None:
        if allowed is not None and fmt not in allowed:
            raise ConfigError(
                f"{path}: the name ends in {suffix or 'no suffix'} but the format is {fmt!r}; "
                f"name it {_suffix_of(fmt)} or choose format {allowed[0]!r}"
            )
        return fmt
    if suffix == "":
        return "db3"
    if allowed is None:
        raise ConfigError(
            f"{path}: cannot tell the log format from suffix {suffix!r}; "
            "name it .mcap, .bag or .db3 (a ROS 2 bag folder)"
        )
    return allowed[0]


def _suffix_of(fmt: LogFormat) -> str:
    return {"mcap": ".mcap", "mcap-ros1": ".mcap", "bag": ".bag", "db3": ".db3"}[fmt]


def log_target(path: Path, fmt: LogFormat) -> Path:
    """The path a log of `fmt` named `path` is written at.

    A ROS 2 bag is a folder holding `<folder>.db3`: `p.db3` becomes the folder `p` (with
    `p/p.db3` inside), not `p.db3/p.db3.db3`. Every other format is written at `path`.
    """
    if fmt == "db3" and path.suffix.lower() == ".db3":
        return path.with_suffix("")
    return path


def ros_time(stamp_ns: int, store: Any) -> Any:
    """A `builtin_interfaces/msg/Time` of `store` for integer nanoseconds (floor division)."""
    sec, nanosec = divmod(int(stamp_ns), _NS_PER_S)
    return store.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


class LogWriter(ABC):
    """An output log being written. Use as a context manager; `close()` publishes it."""

    encoding: Literal["cdr", "ros1"]
    """Serialization of the messages this writer stores."""
    fmt: LogFormat

    def __init__(
        self,
        path: Path,
        overwrite: bool,
        registry: TypeRegistry,
        outputs: OutputSet | None = None,
    ) -> None:
        self.path = path
        self.overwrite = overwrite
        self.registry = registry
        self.store: Any = registry.store
        """rosbags Typestore used to serialise `write_msg` objects and generate definitions."""
        self.topic_types: dict[str, str] = {}
        self.counts: dict[str, int] = {}
        self._closed = True  # nothing to clean up until the temporary output exists
        self._own_outputs = outputs is None
        self._outputs = outputs or OutputSet(
            overwrite=overwrite, overwrite_hint="pass overwrite=True to replace it"
        )
        self._tmp_path = self._outputs.add(path, kind="dir" if self.fmt == "db3" else "file")
        """The output is built here (same file system as the target); the OutputSet moves it."""
        self._closed = False

    # -- topics and messages -------------------------------------------------------------

    def add_topic(self, topic: str, msgtype: str, *, latched: bool = False) -> None:
        """Declare a topic with its message type ('pkg/msg/Name' or 'pkg/Name').

        `latched` marks topics like /tf_static (ROS 1 latching, ROS 2 transient local).
        """
        self._check_open()
        msgtype = normalise_type_name(msgtype)
        if topic in self.topic_types:
            raise ValueError(f"topic {topic!r} already added")
        if not self.registry.knows(msgtype):
            raise UnknownTypeError(f"no definition for message type {msgtype!r}")
        self._add_topic(topic, msgtype, latched)
        self.topic_types[topic] = msgtype
        self.counts[topic] = 0

    def write(self, topic: str, log_time_ns: int, data: bytes | memoryview) -> None:
        """Store one message already serialized in this writer's `encoding`."""
        self._check_open()
        if topic not in self.topic_types:
            raise KeyError(f"topic {topic!r} was not added")
        log_time_ns = int(log_time_ns)
        if not 0 <= log_time_ns <= _MAX_TIME_NS:
            raise ValueError(f"log time {log_time_ns} ns is outside [0, 2^63)")
        self._write(topic, log_time_ns, bytes(data))
        self.counts[topic] += 1

    def serialize(self, msg: Any) -> bytes:
        """Serialize a message object of this writer's typestore in its encoding."""
        msgtype = str(msg.__msgtype__)
        if self.encoding == "ros1":
            return bytes(self.store.serialize_ros1(msg, msgtype))
        return bytes(self.store.serialize_cdr(msg, msgtype))

    def write_msg(self, topic: str, log_time_ns: int, msg: Any) -> None:
        """Serialize `msg` through the typestore and store it; its type must be the topic's."""
        expected = self.topic_types.get(topic)
        if expected is None:
            raise KeyError(f"topic {topic!r} was not added")
        if msg.__msgtype__ != expected:
            raise TypeError(f"topic {topic!r} carries {expected}, got {msg.__msgtype__}")
        self.write(topic, log_time_ns, self.serialize(msg))

    def new_msg(self, msgtype: str, **fields: Any) -> Any:
        """Build a message object; fields not given get zero/empty defaults.

        This keeps callers independent of ROS 1 / ROS 2 differences (e.g. `Header.seq`).
        """
        return _default_msg(self.store, normalise_type_name(msgtype), fields)

    def time(self, stamp_ns: int) -> Any:
        """A `builtin_interfaces/msg/Time` for integer nanoseconds."""
        return ros_time(stamp_ns, self.store)

    def header(self, stamp_ns: int, frame_id: str) -> Any:
        """A `std_msgs/msg/Header` (with seq=0 under ROS 1)."""
        return self.new_msg("std_msgs/msg/Header", stamp=self.time(stamp_ns), frame_id=frame_id)

    # -- life cycle ----------------------------------------------------------------------

    def close(self) -> None:
        """Finish the log; publish it unless an OutputSet given by the caller commits it."""
        if self._closed:
            return
        self._closed = True
        try:
            with self._outputs.writing(self.path):
                self._finish()
        except BaseException:
            with contextlib.suppress(Exception):
                self._discard()  # close what _finish left open (a full disk stops it midway)
            self._remove_temporary()
            raise
        if self._own_outputs:
            self._outputs.commit()

    def abort(self) -> None:
        """Drop everything written; the target is left as it was."""
        if self._closed:
            return
        self._closed = True
        with contextlib.suppress(Exception):
            self._discard()
        self._remove_temporary()

    def _remove_temporary(self) -> None:
        if self._own_outputs:
            self._outputs.discard()
        elif self._tmp_path.is_dir():
            shutil.rmtree(self._tmp_path, ignore_errors=True)
        else:
            self._tmp_path.unlink(missing_ok=True)

    def __enter__(self) -> LogWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def __del__(self) -> None:
        # A writer dropped without close() must not leave a temporary output behind.
        if not getattr(self, "_closed", True):
            self.abort()

    def _check_open(self) -> None:
        if self._closed:
            raise ValueError(f"writer for {self.path} is closed")

    @abstractmethod
    def _add_topic(self, topic: str, msgtype: str, latched: bool) -> None: ...

    @abstractmethod
    def _write(self, topic: str, log_time_ns: int, data: bytes) -> None: ...

    @abstractmethod
    def _finish(self) -> None: ...

    @abstractmethod
    def _discard(self) -> None: ...


class McapLogWriter(LogWriter):
    """MCAP with zstd chunks; ROS 2 (cdr + ros2msg) or ROS 1 (ros1 + ros1msg) profile."""

    def __init__(
        self,
        path: Path,
        overwrite: bool,
        ros1: bool,
        chunk_bytes: int = MCAP_CHUNK_BYTES,
        outputs: OutputSet | None = None,
    ) -> None:
        self.fmt = "mcap-ros1" if ros1 else "mcap"
        super().__init__(path, overwrite, writer_registry(ros1), outputs)
        self.encoding = "ros1" if ros1 else "cdr"
        self._ros1 = ros1
        self._file: BinaryIO = self._tmp_path.open("wb")
        self._mcap: Any = McapRawWriter(
            self._file, chunk_size=chunk_bytes, compression=CompressionType.ZSTD
        )
        self._mcap.start(profile="ros1" if ros1 else "ros2", library="syncaudit")
        self._schema_ids: dict[str, int] = {}
        self._channel_ids: dict[str, int] = {}
        self._sequence: dict[str, int] = {}

    def _schema_id(self, msgtype: str) -> int:
        if msgtype not in self._schema_ids:
            version = 1 if self._ros1 else 2
            msgdef, _digest = self.store.generate_msgdef(msgtype, ros_version=version)
            pkg, _, name = msgtype.split("/")
            self._schema_ids[msgtype] = self._mcap.register_schema(
                name=f"{pkg}/{name}" if self._ros1 else msgtype,
                encoding="ros1msg" if self._ros1 else "ros2msg",
                data=msgdef.encode("utf-8"),
            )
        return self._schema_ids[msgtype]

    def _add_topic(self, topic: str, msgtype: str, latched: bool) -> None:
        metadata = {"latching": "1"} if latched and self._ros1 else {}
        if latched and not self._ros1:
            metadata = {"offered_qos_profiles": _TRANSIENT_LOCAL_YAML}
        self._channel_ids[topic] = self._mcap.register_channel(
            topic=topic,
            message_encoding=self.encoding,
            schema_id=self._schema_id(msgtype),
            metadata=metadata,
        )
        self._sequence[topic] = 0

    def _write(self, topic: str, log_time_ns: int, data: bytes) -> None:
        self._mcap.add_message(
            channel_id=self._channel_ids[topic],
            log_time=log_time_ns,
            data=data,
            publish_time=log_time_ns,
            sequence=self._sequence[topic],
        )
        self._sequence[topic] += 1

    def _finish(self) -> None:
        self._mcap.finish()
        self._file.flush()
        os.fsync(self._file.fileno())
        self._file.close()

    def _discard(self) -> None:
        self._file.close()


class Rosbag2LogWriter(LogWriter):
    """A ROS 2 bag directory (`metadata.yaml` + `<name>.db3`), sqlite3 storage, CDR."""

    fmt: LogFormat = "db3"
    encoding: Literal["cdr", "ros1"] = "cdr"

    def __init__(self, path: Path, overwrite: bool, outputs: OutputSet | None = None) -> None:
        super().__init__(path, overwrite, writer_registry(ros1=False), outputs)
        # Built as <tmp>/<name>/<name>.db3 so that the bag keeps its final file names.
        self._bag = Rosbag2Writer(self._tmp_path, version=Rosbag2Writer.VERSION_LATEST)
        try:
            self._bag.open()
        except BaseException:
            self.abort()  # a full disk while creating the database: close it, drop it
            raise
        self._connections: dict[str, Any] = {}

    def _add_topic(self, topic: str, msgtype: str, latched: bool) -> None:
        qos = [_transient_local_qos()] if latched else []
        self._connections[topic] = self._bag.add_connection(
            topic, msgtype, typestore=self.store, offered_qos_profiles=qos
        )

    def _write(self, topic: str, log_time_ns: int, data: bytes) -> None:
        self._bag.write(self._connections[topic], log_time_ns, data)

    def _finish(self) -> None:
        self._bag.set_custom_data(BAG2_KEY, WRITTEN_BY)  # the mark `--overwrite` looks for
        self._bag.close()

    def _discard(self) -> None:
        # rosbags has no abort for sqlite3 storage: close its connection, the file goes.
        storage = getattr(self._bag, "storage", None)
        conn = getattr(storage, "conn", None)
        if conn is not None:
            conn.close()


BagCompression = Literal["none", "lz4", "bz2"]
"""ROS 1 bag chunk compression (`rosbag record --lz4 / --bz2`)."""


class Rosbag1LogWriter(LogWriter):
    """A ROS 1 bag (chunks uncompressed, or lz4 / bz2 as `rosbag record` writes them), ROS 1
    serialization."""

    fmt: LogFormat = "bag"
    encoding: Literal["cdr", "ros1"] = "ros1"

    def __init__(
        self,
        path: Path,
        overwrite: bool,
        outputs: OutputSet | None = None,
        compression: BagCompression = "none",
    ) -> None:
        super().__init__(path, overwrite, writer_registry(ros1=True), outputs)
        self._bag = Rosbag1Writer(self._tmp_path)
        if compression != "none":
            self._bag.set_compression(Rosbag1Writer.CompressionFormat[compression.upper()])
        try:
            self._bag.open()
        except BaseException:
            self.abort()
            raise
        self._connections: dict[str, Any] = {}

    def _add_topic(self, topic: str, msgtype: str, latched: bool) -> None:
        self._connections[topic] = self._bag.add_connection(
            topic, msgtype, typestore=self.store, latching=1 if latched else None
        )

    def _write(self, topic: str, log_time_ns: int, data: bytes) -> None:
        self._bag.write(self._connections[topic], log_time_ns, data)

    def _finish(self) -> None:
        self._bag.close()
        mark_bag1(self._tmp_path)  # the mark `--overwrite` looks for

    def _discard(self) -> None:
        if self._bag.bio is not None:
            self._bag.bio.close()


def open_writer(
    path: str | Path,
    fmt: LogFormat | None = "mcap",
    *,
    overwrite: bool = False,
    mcap_chunk_bytes: int = MCAP_CHUNK_BYTES,
    outputs: OutputSet | None = None,
    bag_compression: BagCompression = "none",
) -> LogWriter:
    """Start writing a log at `path` in `fmt` (None: infer from the suffix); a ROS 1 bag's
    chunks compressed as `bag_compression` says.

    For 'db3' `path` is the bag directory to create, exactly as given (the CLI names it
    with `log_target`). With `outputs`
    the log is written into that OutputSet's temporary and committed with the set's other
    outputs; without, `close()` publishes it on its own.

    Raises:
        OutputError: `path` exists and `overwrite` is False, or it is a folder that is not
            a bag this tool writes, or its folder is missing.
    """
    path = Path(path)
    fmt = infer_format(path, fmt)
    if fmt == "mcap":
        return McapLogWriter(path, overwrite, False, mcap_chunk_bytes, outputs)
    if fmt == "mcap-ros1":
        return McapLogWriter(path, overwrite, True, mcap_chunk_bytes, outputs)
    if fmt == "db3":
        return Rosbag2LogWriter(path, overwrite, outputs)
    if fmt == "bag":
        return Rosbag1LogWriter(path, overwrite, outputs, bag_compression)
    raise ConfigError(f"unknown log format {fmt!r}; expected one of {', '.join(FORMATS)}")


# -- helpers ------------------------------------------------------------------------------

ROS1_FROM_ROS2_PACKAGES = frozenset({"tf2_msgs"})
"""Packages that exist in ROS 1 with the same definitions but are missing from rosbags'
ROS 1 (Noetic) typestore; their types are taken from the ROS 2 store (e.g. /tf_static's
tf2_msgs/msg/TFMessage)."""


def writer_registry(ros1: bool) -> TypeRegistry:
    """The readers' type registry, completed for ROS 1 with `ROS1_FROM_ROS2_PACKAGES`."""
    registry = TypeRegistry(ros1=ros1, eager=True)
    if ros1:
        ros2 = get_typestore(Stores.ROS2_HUMBLE)
        extra = {
            name: fielddef
            for name, fielddef in ros2.fielddefs.items()
            if name.split("/")[0] in ROS1_FROM_ROS2_PACKAGES and not registry.knows(name)
        }
        if extra:
            registry.add_types(extra)
    return registry


_TRANSIENT_LOCAL_YAML = (
    "- history: 1\n  depth: 1\n  reliability: 1\n  durability: 1\n"
    "  deadline:\n    sec: 2147483647\n    nsec: 4294967295\n"
    "  lifespan:\n    sec: 2147483647\n    nsec: 4294967295\n"
    "  liveliness: 1\n"
    "  liveliness_lease_duration:\n    sec: 2147483647\n    nsec: 4294967295\n"
    "  avoid_ros_namespace_conventions: false\n"
)
"""rosbag2's QoS YAML for a latched (/tf_static style) publisher, as MCAP channel metadata."""


def _transient_local_qos() -> Qos:
    """QoS of a latched publisher: reliable, transient local, keep last 1."""
    infinite = RosbagsQosTime(sec=2147483647, nsec=4294967295)
    return Qos(
        history=QosHistory.KEEP_LAST,
        depth=1,
        reliability=QosReliability.RELIABLE,
        durability=QosDurability.TRANSIENT_LOCAL,
        deadline=infinite,
        lifespan=infinite,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=infinite,
        avoid_ros_namespace_conventions=False,
    )


_BASE_DEFAULTS: dict[str, Any] = {
    "bool": False,
    "string": "",
    "float32": 0.0,
    "float64": 0.0,
}

_NUMPY_ARRAY_TYPES: dict[str, type[np.generic]] = {
    "bool": np.bool_,
    "byte": np.uint8,
    "char": np.uint8,
    "int8": np.int8,
    "uint8": np.uint8,
    "int16": np.int16,
    "uint16": np.uint16,
    "int32": np.int32,
    "uint32": np.uint32,
    "int64": np.int64,
    "uint64": np.uint64,
    "float32": np.float32,
    "float64": np.float64,
}


def _default_value(store: Any, node: tuple[Any, Any]) -> Any:
    """Zero value of one field description of rosbags' fielddefs."""
    kind, detail = node
    kind_name = getattr(kind, "name", str(kind))
    if kind_name == "BASE":
        base = detail[0]
        return _BASE_DEFAULTS.get(base, 0)
    if kind_name == "NAME":
        return _default_msg(store, detail, {})
    # ARRAY (fixed length) or SEQUENCE: detail = (element node, length)
    element, length = detail
    element_kind = getattr(element[0], "name", str(element[0]))
    count = int(length) if kind_name == "ARRAY" else 0
    if element_kind == "BASE" and element[1][0] in _NUMPY_ARRAY_TYPES:
        return np.zeros(count, dtype=_NUMPY_ARRAY_TYPES[element[1][0]])
    return [_default_value(store, element) for _ in range(count)]


def _default_msg(store: Any, msgtype: str, fields: dict[str, Any]) -> Any:
    """Instantiate `msgtype` with `fields`, filling the missing ones with zero values."""
    if msgtype not in store.fielddefs:
        raise UnknownTypeError(f"no definition for message type {msgtype!r}")
    _consts, fielddefs = store.fielddefs[msgtype]
    known = {name for name, _ in fielddefs}
    unknown = set(fields) - known
    if unknown:
        raise TypeError(f"{msgtype} has no field(s) {sorted(unknown)}")
    values = {
        name: fields[name] if name in fields else _default_value(store, node)
        for name, node in fielddefs
    }
    return store.types[msgtype](**values)
