"""Message definitions for a log: the log's own first, then `schemas/`, then ROS defaults.

rosbags' type system is imported where a definition is first parsed or a registry built,
not with this module: an audit whose messages all have struct readers never needs it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from functools import cache
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

from syncaudit.errors import LogReadError, UnknownTypeError

if TYPE_CHECKING:
    from rosbags.interfaces.typing import Typesdict
    from rosbags.typesys.store import Typestore

# Schema encodings that carry ROS message definitions; anything else (jsonschema,
# protobuf, ...) describes non-ROS data that rosbags cannot deserialize.
MSG_SCHEMA_ENCODINGS = frozenset({"ros1msg", "ros2msg", "msg"})
IDL_SCHEMA_ENCODINGS = frozenset({"ros2idl", "idl"})
MESSAGE_ENCODINGS = frozenset({"cdr", "ros1"})
_SECTION = "=" * 80 + "\n"
"""Separator between the per-type sections of a concatenated definition."""


def schemas_dir() -> Path:
    """Folder of the project's .msg definitions (shipped in the wheel as syncaudit.schemas)."""
    return Path(str(resources.files("syncaudit.schemas")))


@cache
def _project_schemas() -> tuple[Typesdict, tuple[str, ...]]:
    """Parse `schemas/<pkg>/msg/<Name>.msg` once: (types, one-line problems of bad files).

    A bad file is reported, not raised: one broken definition must not make every log
    unreadable, only the types that need it.
    """
    from rosbags.typesys import get_types_from_msg

    types: Typesdict = {}
    problems: list[str] = []
    for path in sorted(schemas_dir().glob("*/msg/*.msg")):
        name = f"{path.parent.parent.name}/msg/{path.stem}"
        try:
            types.update(get_types_from_msg(path.read_text(encoding="utf-8"), name))
        except Exception as exc:  # rosbags raises several parser error types
            problems.append(f"schemas/{path.parent.parent.name}/msg/{path.name}: {one_line(exc)}")
    return types, tuple(problems)


def project_types() -> Typesdict:
    """All message types under `schemas/<pkg>/msg/<Name>.msg` (unparseable files left out)."""
    return dict(_project_schemas()[0])


def project_schema_problems() -> tuple[str, ...]:
    """One line per file under `schemas/` that could not be parsed."""
    return _project_schemas()[1]


def parse_definition(encoding: str, text: str, name: str) -> Typesdict:
    """Parse one MCAP schema or rosbag connection definition into rosbags' type dict.

    `encoding` is the MCAP schema encoding ('ros1msg', 'ros2msg', 'ros2idl') or 'msg'/'idl';
    other encodings hold no ROS definitions and give an empty dict.
    """
    from rosbags.typesys import get_types_from_idl, get_types_from_msg

    if encoding in IDL_SCHEMA_ENCODINGS:
        if not text.startswith(f"{_SECTION}IDL: "):
            return dict(get_types_from_idl(text))
        # rosbag2 concatenates one section per type: '====...\nIDL: pkg/msg/Name\n<idl>'
        types: Typesdict = {}
        for section in text.split(_SECTION)[1:]:
            _header, _, idl = section.partition("\n")
            types.update(get_types_from_idl(idl))
        return types
    if encoding in MSG_SCHEMA_ENCODINGS:
        return dict(get_types_from_msg(text, normalise_type_name(name)))
    return {}


def normalise_type_name(name: str) -> str:
    """'pkg/Name' (ROS 1) -> 'pkg/msg/Name' (the form rosbags and schemas/ use)."""
    parts = name.split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return name


def one_line(exc: BaseException) -> str:
    """An exception's text folded onto one line (type name if it has no text)."""
    return " ".join(str(exc).split()) or type(exc).__name__


@dataclass(frozen=True, slots=True)
class Definition:
    """One message definition a log carries (an MCAP schema, a bag connection's or a
    rosbag2 database's definition), as its reader found it."""

    msgtype: str
    """The type it defines ('pkg/msg/Name', or ROS 1's 'pkg/Name')."""
    encoding: str
    """'ros1msg', 'ros2msg', 'ros2idl', 'msg' or 'idl' (anything else defines no ROS type)."""
    text: str | bytes
    """The definition (bytes are decoded as UTF-8 when it is parsed)."""
    where: str
    """How a warning about it begins: "definition of 'pkg/msg/Name'", or the file and schema."""


def log_types(definitions: Iterable[Definition], warn: Callable[[str, str], None]) -> Typesdict:
    """The types a log's own definitions give, the first definition of a type winning; one
    that cannot be parsed is a 'bad-schema' warning, not an error (it must not stop an
    audit that does not deserialise that type)."""
    types: Typesdict = {}
    for item in definitions:
        if not item.text or normalise_type_name(item.msgtype) in types:
            continue
        try:
            text = item.text.decode("utf-8") if isinstance(item.text, bytes) else item.text
            parsed = parse_definition(item.encoding, text, item.msgtype)
        except Exception as exc:  # rosbags raises several parser error types
            warn("bad-schema", f"{item.where} unreadable: {one_line(exc)}")
            continue
        types.update({k: v for k, v in parsed.items() if k not in types})
    return types


def _nested_names(definition: object) -> list[str]:
    """Type names ('pkg/msg/Name') mentioned anywhere in a rosbags field definition."""
    found: list[str] = []
    stack: list[object] = [definition]
    while stack:
        item = stack.pop()
        if isinstance(item, str):
            if item.count("/") == 2:
                found.append(item)
        elif isinstance(item, tuple | list):
            stack.extend(item)
    return found


class TypeRegistry:
    """Types known for one log, built as: log definitions, then project schemas, then ROS."""

    def __init__(self, ros1: bool, log_types: Typesdict | None = None, eager: bool = False) -> None:
        """`eager` registers every known type at once (writers build arbitrary messages);
        otherwise a type and what it nests are registered when first deserialised."""
        from rosbags.typesys import Stores, get_typestore

        base = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        available: dict[str, Any] = dict(log_types or {})
        for source in (project_types(), base.fielddefs):
            available.update({k: v for k, v in source.items() if k not in available})
        self._available = available
        self.store: Typestore = get_typestore(Stores.EMPTY)
        self.ros1 = ros1
        self.problems: tuple[str, ...] = project_schema_problems()
        """Unparseable files under schemas/, for the log to report as warnings."""
        self._eager = eager
        if eager:
            self.store.register(available)

    def add_types(self, types: Typesdict) -> None:
        """Make more definitions available (registered at once when the registry is eager)."""
        new = {k: v for k, v in types.items() if k not in self._available}
        self._available.update(new)
        if self._eager and new:
            self.store.register(new)

    def knows(self, msgtype: str) -> bool:
        """True where a definition for `msgtype` is available."""
        return msgtype in self._available

    def ensure(self, msgtype: str) -> None:
        """Register `msgtype` and every type it nests (code generation is per type, so
        registering only what a log deserialises keeps opening a log cheap)."""
        if msgtype in self.store.fielddefs:
            return
        needed: dict[str, Any] = {}
        stack = [msgtype]
        while stack:
            name = stack.pop()
            if name in needed or name in self.store.fielddefs or name not in self._available:
                continue
            needed[name] = self._available[name]
            stack.extend(_nested_names(needed[name]))
        self.store.register(needed)

    def deserialize(self, data: bytes | memoryview, msgtype: str, encoding: str) -> object:
        """Deserialize one message with rosbags.

        Raises UnknownTypeError when `msgtype` (or a type it nests) has no definition or the
        encoding is not a ROS one, LogReadError when the bytes do not fit the definition.
        """
        if encoding not in MESSAGE_ENCODINGS:
            raise UnknownTypeError(
                f"message encoding {encoding!r} of {msgtype!r} is not ROS (cdr/ros1); "
                "cannot deserialize it"
            )
        if not self.knows(msgtype):
            raise UnknownTypeError(
                f"no definition for message type {msgtype!r} in the log or in schemas/"
            )
        try:
            self.ensure(msgtype)
            if encoding == "ros1":
                return self.store.deserialize_ros1(data, msgtype)
            return self.store.deserialize_cdr(data, msgtype)
        except KeyError as exc:
            # rosbags looks nested types up lazily: a missing one surfaces as KeyError.
            raise UnknownTypeError(
                f"no definition for {exc.args[0]!r} (used by {msgtype!r}) in the log or in schemas/"
            ) from exc
        except Exception as exc:  # rosbags' SerdeError, struct.error, IndexError, ...
            raise LogReadError(
                f"a {msgtype!r} message does not match its definition: {one_line(exc)}"
            ) from exc
