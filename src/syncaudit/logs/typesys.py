"""Message definitions for a log: the log's own first, then `schemas/`, then ROS defaults."""

from __future__ import annotations

from functools import cache
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

from syncaudit.errors import UnknownTypeError

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

    Typesdict = dict[str, object]


def schemas_dir() -> Path:
    """Folder of the project's .msg definitions (shipped in the wheel as syncaudit.schemas)."""
    return Path(str(resources.files("syncaudit.schemas")))


@cache
def project_types() -> dict[str, object]:
    """All message types under `schemas/<pkg>/msg/<Name>.msg`, parsed once."""
    types: dict[str, object] = {}
    for path in sorted(schemas_dir().glob("*/msg/*.msg")):
        name = f"{path.parent.parent.name}/msg/{path.stem}"
        types.update(get_types_from_msg(path.read_text(encoding="utf-8"), name))
    return types


def parse_definition(encoding: str, text: str, name: str) -> dict[str, object]:
    """Parse one MCAP schema or rosbag connection definition into rosbags' type dict."""
    if encoding == "ros2idl":
        return dict(get_types_from_idl(text))
    return dict(get_types_from_msg(text, name))


def normalise_type_name(name: str) -> str:
    """'pkg/Name' (ROS 1) -> 'pkg/msg/Name' (the form rosbags and schemas/ use)."""
    parts = name.split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return name


class TypeRegistry:
    """Types known for one log, built as: log definitions, then project schemas, then ROS."""

    def __init__(self, ros1: bool, log_types: dict[str, object] | None = None) -> None:
        base = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        store = get_typestore(Stores.EMPTY)
        if log_types:
            store.register(log_types)
        extra = {k: v for k, v in project_types().items() if k not in store.fielddefs}
        if extra:
            store.register(extra)
        rest = {k: v for k, v in base.fielddefs.items() if k not in store.fielddefs}
        store.register(rest)
        self.store: Typestore = store
        self.ros1 = ros1

    def knows(self, msgtype: str) -> bool:
        """True where a definition for `msgtype` is available."""
        return msgtype in self.store.fielddefs

    def deserialize(self, data: bytes | memoryview, msgtype: str, encoding: str) -> object:
        """Deserialize one message with rosbags; raises UnknownTypeError for unknown types."""
        if not self.knows(msgtype):
            raise UnknownTypeError(
                f"no definition for message type {msgtype!r} in the log or in schemas/"
            )
        if encoding == "ros1":
            return self.store.deserialize_ros1(data, msgtype)
        return self.store.deserialize_cdr(data, msgtype)
