"""Config files: one strict model base and one loader for YAML, TOML and JSON.

Every config of the project (rig files, the calibration's config, simulator settings)
derives from `ConfigModel`: frozen, unknown keys refused (with the nearest known key
suggested), non-finite floats refused, and any validation failure raised as a one-line
`ConfigError` (exit 6). `load_mapping` reads a file into a dict with the same guards for
every format: a size cap, UTF-8 (or UTF-16/32 with a byte-order mark), bounded nesting.
"""

from __future__ import annotations

import contextvars
import difflib
import json
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, Self, TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, ValidationError

from syncaudit.errors import ConfigError, InputOpenError

MAX_CONFIG_BYTES = 1 << 20
"""Largest config file read (1 MiB): a rig of a thousand cameras is about 200 KB."""

MAX_NESTING = 100
"""Deepest nesting of mappings and lists accepted in a config file (rigs use 4)."""

MAX_ALIASES = 1_000
"""Most YAML alias uses (`*name`) in one document: a rig sharing one intrinsics block
between cameras uses one per camera; the billion-laughs bomb needs 72 for 9**9 values."""

MAX_VALUES = 30_000
"""Most values (mappings, lists, scalars) in one document, as written and after alias
expansion: bench_many_cameras' 2,000-camera rig holds 22,011, the alias bomb 435 million.
Composing YAML costs 8-25 us a value on this 2-core machine (40,000 took 0.8-1.1 s at load
average 11), so 30,000 keeps a refusal within the 1 s bound."""

MAX_KEYS = 5_000
"""Most keys in one mapping (a rig's thousand cameras are list items, not keys; a policy's
per-vehicle rigs a few hundred)."""

MAX_SCALAR_CHARS = 65_536
"""Longest single string or number in a config (a path is at most 4,096 bytes)."""

_BOMS: tuple[tuple[bytes, str], ...] = (
    (b"\xff\xfe\x00\x00", "utf-32-le"),
    (b"\x00\x00\xfe\xff", "utf-32-be"),
    (b"\xef\xbb\xbf", "utf-8-sig"),
    (b"\xff\xfe", "utf-16-le"),
    (b"\xfe\xff", "utf-16-be"),
)

M = TypeVar("M", bound="ConfigModel")

try:  # libyaml's event parser where PyYAML has it (3-4x faster than the pure-Python one)
    from yaml._yaml import CParser as _EventSource
except ImportError:  # pragma: no cover - PyYAML built without libyaml

    class _EventSource(yaml.reader.Reader, yaml.scanner.Scanner, yaml.parser.Parser):  # type: ignore[no-redef]
        """The pure-Python reader, scanner and parser: YAML events from text."""

        def __init__(self, stream: str) -> None:
            yaml.reader.Reader.__init__(self, stream)
            yaml.scanner.Scanner.__init__(self)
            yaml.parser.Parser.__init__(self)


class _BoundedLoader(
    yaml.composer.Composer,
    _EventSource,
    yaml.constructor.SafeConstructor,
    yaml.resolver.Resolver,
):
    """A safe YAML loader whose composer counts as it goes: it stops at the first node past
    `max_values`, the first alias past MAX_ALIASES or the first level past MAX_NESTING, so
    a hostile file costs at most that many nodes (~10 us each), never its whole size."""

    def __init__(self, text: str, max_values: int) -> None:
        _EventSource.__init__(self, text)
        yaml.composer.Composer.__init__(self)
        yaml.constructor.SafeConstructor.__init__(self)
        yaml.resolver.Resolver.__init__(self)
        self.max_values = max_values
        self.nodes = 0
        self.aliases = 0
        self.level = 0

    def compose_node(self, parent: yaml.Node | None, index: Any) -> yaml.Node:
        """Compose one node, refusing the document once it passes a bound."""
        self.nodes += 1
        if self.nodes > self.max_values:
            raise self._refused(f"more than {self.max_values} values")
        if index is None and isinstance(parent, yaml.MappingNode):
            if len(parent.value) >= MAX_KEYS:
                raise self._refused(f"a mapping of more than {MAX_KEYS} keys")
        elif self.check_event(yaml.AliasEvent):
            self.aliases += 1
            if self.aliases > MAX_ALIASES:
                raise self._refused(f"more than {MAX_ALIASES} aliases")
        self.level += 1
        try:
            if self.level > MAX_NESTING:
                raise self._refused(f"nested deeper than {MAX_NESTING} levels")
            node = super().compose_node(parent, index)
            assert node is not None  # the composer returns None only at the stream's end
            return node
        finally:
            self.level -= 1

    def _refused(self, why: str) -> ConfigError:
        """`line L column C: why` at the next event."""
        mark = getattr(self.peek_event(), "start_mark", None)
        where = f"line {mark.line + 1} column {mark.column + 1}: " if mark is not None else ""
        return ConfigError(where + why)


_DEPTH: contextvars.ContextVar[int] = contextvars.ContextVar("config_depth", default=0)
"""How many ConfigModel validations are running: pydantic calls a custom `__init__` for
nested models too, and only the outermost turns the error into a ConfigError (with the
whole key path)."""


class ConfigModel(BaseModel):
    """Frozen, strict-keys, finite-floats base; validation failures become `ConfigError`."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    def __init__(self, /, **data: Any) -> None:
        nested = _DEPTH.get() > 0
        token = _DEPTH.set(_DEPTH.get() + 1)
        try:
            super().__init__(**data)
        except ValidationError as exc:
            if nested:  # inside another model's validation: let that one add the key path
                raise
            raise _config_error(exc, type(self)) from None
        finally:
            _DEPTH.reset(token)

    @classmethod
    def model_validate(cls, *args: Any, **kwargs: Any) -> Self:
        """pydantic's model_validate, with failures as one-line `ConfigError`s."""
        nested = _DEPTH.get() > 0
        token = _DEPTH.set(_DEPTH.get() + 1)
        try:
            return super().model_validate(*args, **kwargs)
        except ValidationError as exc:
            if nested:
                raise
            raise _config_error(exc, cls) from None
        finally:
            _DEPTH.reset(token)

    @classmethod
    def from_mapping(cls, data: Any) -> Self:
        """Validate a mapping (e.g. parsed YAML), raising `ConfigError` on nonsense."""
        if not isinstance(data, dict):
            raise ConfigError(
                f"invalid {cls.__name__}: expected a mapping, got {type(data).__name__}"
            )
        return cls.model_validate(data)


def _config_error(exc: ValidationError, model: type[BaseModel]) -> ConfigError:
    """A model's validation failure as a one-line ConfigError that keeps where and what."""
    summary = validation_summary(exc, model)
    first = exc.errors()[0]
    return ConfigError(
        f"invalid {model.__name__}: {summary}",
        key_path=tuple(first["loc"]),
        detail=summary.split(": ", 1)[-1],
    )


def validation_summary(exc: ValidationError, model: type[BaseModel] | None = None) -> str:
    """A pydantic ValidationError on one line: `key.path: message (+N more)`.

    An unknown key names the nearest known one when `model` is given (`imag_topic` ->
    "did you mean 'image_topic'?").
    """
    errors = exc.errors()
    first = errors[0]
    loc = tuple(first["loc"])
    where = ".".join(str(part) for part in loc) or "(top level)"
    message = " ".join(str(first["msg"]).split()).removeprefix("Value error, ")
    if first["type"] == "extra_forbidden" and loc:
        message = "unknown key"
        known = _known_keys(model, loc[:-1]) if model is not None else []
        close = difflib.get_close_matches(str(loc[-1]), known, n=1, cutoff=0.6)
        if close:
            message += f" (did you mean {close[0]!r}?)"
        elif known:
            message += f" (known keys: {', '.join(known)})"
    more = f" (+{len(errors) - 1} more)" if len(errors) > 1 else ""
    return f"{where}: {message}{more}"


def _model_in(annotation: Any) -> type[BaseModel] | None:
    """The pydantic model an annotation holds (directly, in a list/tuple/dict or Optional)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    origin = typing.get_origin(annotation)
    if origin is None:
        return None
    if origin in (typing.Union, types.UnionType, list, tuple, dict, typing.Annotated):
        for arg in typing.get_args(annotation):
            found = _model_in(arg)
            if found is not None:
                return found
    return None


def _known_keys(model: type[BaseModel] | None, path: tuple[Any, ...]) -> list[str]:
    """The keys a mapping at `path` (a validation error location) may hold."""
    for part in path:
        if model is None:
            return []
        if isinstance(part, int):
            continue  # an index into a list of models
        field = model.model_fields.get(str(part))
        model = _model_in(field.annotation) if field is not None else None
    return sorted(model.model_fields) if model is not None else []


def read_text(path: Path, *, what: str = "config file", max_bytes: int = MAX_CONFIG_BYTES) -> str:
    """A config file's text: size-capped, UTF-8 or UTF-16/32 with a byte-order mark.

    Raises:
        InputOpenError: the file cannot be opened (exit 2).
        ConfigError: larger than `max_bytes`, or not text.
    """
    try:
        with path.open("rb") as handle:
            # in 64 KiB reads: read(max_bytes + 1) would allocate all of max_bytes up front
            parts: list[bytes] = []
            held = 0
            while held <= max_bytes and (part := handle.read(min(1 << 16, max_bytes + 1 - held))):
                parts.append(part)
                held += len(part)
            data = b"".join(parts)
    except OSError as exc:  # missing, a directory, no permission: cannot be opened (exit 2)
        raise InputOpenError(f"{path}: cannot read {what} ({exc.strerror or exc})") from None
    return decode_text(data, path, what=what, max_bytes=max_bytes)


def decode_text(
    data: bytes, path: str | Path, *, what: str = "config file", max_bytes: int = MAX_CONFIG_BYTES
) -> str:
    """A config's bytes as text (from a file or a URL): size-capped, UTF-8 or UTF-16/32 with
    a byte-order mark; ConfigError naming `path` otherwise."""
    if len(data) > max_bytes:
        raise ConfigError(
            f"{path}: {what} larger than {max_bytes // 1024} KiB; refusing to read it"
        )
    encoding = next((name for bom, name in _BOMS if data.startswith(bom)), "utf-8")
    if encoding == "utf-8" and b"\x00" in data:
        raise ConfigError(
            f"{path}: {what} holds NUL bytes (UTF-16 without a byte-order mark?); save it as UTF-8"
        )
    try:
        return data.decode(encoding)
    except UnicodeDecodeError as exc:
        raise ConfigError(
            f"{path}: {what} is not {encoding.upper().removesuffix('-SIG')} text "
            f"(byte 0x{data[exc.start]:02x} at offset {exc.start}); save it as UTF-8"
        ) from None


def _yaml_children(node: yaml.Node) -> list[yaml.Node]:
    """A composed YAML node's children: items of a list, keys and values of a mapping."""
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    if isinstance(node, yaml.MappingNode):
        return [part for pair in node.value for part in pair]
    return []


def _check_yaml_node(node: yaml.Node) -> None:
    """One node's own bounds: scalar size, key count, no key given twice."""
    if isinstance(node, yaml.ScalarNode):
        if len(node.value) > MAX_SCALAR_CHARS:
            raise ConfigError(
                f"{_at(node)}a value of {len(node.value)} characters (more than {MAX_SCALAR_CHARS})"
            )
        return
    if not isinstance(node, yaml.MappingNode):
        return
    if len(node.value) > MAX_KEYS:
        raise ConfigError(f"{_at(node)}a mapping of {len(node.value)} keys (more than {MAX_KEYS})")
    seen: set[tuple[str, str]] = set()
    for key, _ in node.value:
        if not isinstance(key, yaml.ScalarNode) or key.tag == "tag:yaml.org,2002:merge":
            continue
        ident = (key.tag, key.value)
        if ident in seen:
            raise ConfigError(
                f"{_at(key)}key {key.value!r} given twice (the second would silently win)"
            )
        seen.add(ident)


def _at(node: yaml.Node) -> str:
    """`line L column C: ` for a YAML node."""
    mark = node.start_mark
    return f"line {mark.line + 1} column {mark.column + 1}: "


def check_yaml_graph(root: yaml.Node, *, max_values: int = MAX_VALUES) -> None:
    """Refuse a composed YAML document that would be too big once its aliases expand.

    Walks the node graph once (each shared node once, its expanded size remembered), so the
    check costs the document's size, not its expansion's: the nine-level alias bomb is
    refused after 82 nodes. Raises ConfigError (no path) for too many aliases or values,
    nesting past MAX_NESTING, a recursive alias, and each node's `_check_yaml_node` bounds.
    """
    expanded: dict[int, tuple[int, int]] = {}  # id(node) -> (values, depth)
    on_path: set[int] = set()
    aliases = 0
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, done = stack.pop()
        key = id(node)
        children = _yaml_children(node)
        if done:
            values = 1 + sum(expanded[id(child)][0] for child in children)
            depth = 1 + max((expanded[id(child)][1] for child in children), default=0)
            on_path.discard(key)
            if values > max_values:
                raise ConfigError(
                    f"{_at(node)}expands to more than {max_values} values (an alias bomb?)"
                )
            if depth > MAX_NESTING:
                raise ConfigError(f"{_at(node)}nested deeper than {MAX_NESTING} levels")
            expanded[key] = (values, depth)
            continue
        if key in expanded:
            aliases += 1
            if aliases > MAX_ALIASES:
                raise ConfigError(f"{_at(node)}more than {MAX_ALIASES} aliases")
            continue
        if key in on_path:
            raise ConfigError(f"{_at(node)}an alias that contains itself")
        _check_yaml_node(node)
        on_path.add(key)
        stack.append((node, True))
        stack.extend((child, False) for child in children)


def _parse_yaml(text: str, max_values: int) -> Any:
    """Compose (bounded), check the graph, then construct a YAML document."""
    loader = _BoundedLoader(text, max_values)
    try:
        root = loader.get_single_node()
        if root is None:
            return None
        check_yaml_graph(root, max_values=max_values)
        return loader.construct_document(root)
    finally:
        loader.dispose()


def unique_pairs(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object's pairs as a dict, refusing a key given twice or too many keys."""
    if len(pairs) > MAX_KEYS:
        raise ConfigError(f"an object of {len(pairs)} keys (more than {MAX_KEYS})")
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise ConfigError(f"key {key!r} given twice (the second would silently win)")
        out[key] = value
    return out


def _check_tree(value: Any, max_values: int) -> None:
    """Bounds of parsed JSON/TOML data (no sharing there): values, depth, keys, scalars."""
    count = 0
    stack: list[tuple[Any, int]] = [(value, 1)]
    while stack:
        item, depth = stack.pop()
        count += 1
        if count > max_values:
            raise ConfigError(f"more than {max_values} values")
        if isinstance(item, dict):
            if len(item) > MAX_KEYS:
                raise ConfigError(f"a mapping of {len(item)} keys (more than {MAX_KEYS})")
            children: list[Any] = [*item.keys(), *item.values()]
        elif isinstance(item, list):
            children = item
        else:
            if isinstance(item, str) and len(item) > MAX_SCALAR_CHARS:
                raise ConfigError(
                    f"a value of {len(item)} characters (more than {MAX_SCALAR_CHARS})"
                )
            continue
        if depth > MAX_NESTING:
            raise ConfigError(f"nested deeper than {MAX_NESTING} levels")
        stack.extend((child, depth + 1) for child in children)


def _parse_error(exc: Exception) -> str:
    """A parser's error on one line, with the line and column where it has them."""
    if isinstance(exc, yaml.MarkedYAMLError) and exc.problem_mark is not None:
        mark = exc.problem_mark
        problem = exc.problem or exc.context or "cannot parse"
        if problem == "exceeded maximum nesting depth":
            problem = "nested too deeply to be a config"
        return f"line {mark.line + 1} column {mark.column + 1}: {problem}"
    text = " ".join(str(exc).split())
    return text or type(exc).__name__


def parse_text(text: str, kind: str, *, max_values: int = MAX_VALUES) -> Any:
    """Parse config text as `kind` ("YAML", "JSON" or "TOML"), bounded in time and memory.

    Every format gets the same bounds: MAX_ALIASES, MAX_VALUES (after alias expansion),
    MAX_NESTING, MAX_KEYS per mapping, MAX_SCALAR_CHARS, and no key given twice.
    `max_values` is raised only for files a tool writes at scale (a bag's metadata.yaml).

    Raises:
        ConfigError: one line without the file's name (callers add it).
    """
    try:
        if kind == "TOML":
            raw: Any = tomllib.loads(text)  # refuses duplicate keys itself
        elif kind == "JSON":
            raw = json.loads(text, object_pairs_hook=unique_pairs)
        else:
            return _parse_yaml(text, max_values)
    except RecursionError:
        raise ConfigError("nested too deeply to be a config") from None
    except ConfigError:
        raise
    except (yaml.YAMLError, tomllib.TOMLDecodeError, ValueError) as exc:
        raise ConfigError(f"not valid {kind}: {_parse_error(exc)}") from None
    _check_tree(raw, max_values)
    return raw


def kind_of(path: Path) -> str:
    """The config format a file's suffix names: TOML, JSON, else YAML."""
    return {".toml": "TOML", ".json": "JSON"}.get(path.suffix.lower(), "YAML")


def load_mapping(path: str | Path, *, what: str = "config file") -> dict[str, Any]:
    """Parse a YAML (.yaml/.yml/other), TOML (.toml) or JSON (.json) file into a dict.

    Raises:
        ConfigError: naming the file, for anything but a readable mapping within the
            bounds of `parse_text`.
    """
    path = Path(path)
    return mapping_from_text(read_text(path, what=what), path, what=what)


def mapping_from_text(text: str, path: str | Path, *, what: str = "config file") -> dict[str, Any]:
    """Parse config text read from `path` (its suffix names the format) into a dict;
    ConfigError naming `path`, as `load_mapping`."""
    try:
        raw = parse_text(text, kind_of(Path(path)))
    except ConfigError as exc:
        raise ConfigError(f"{path}: {_refused(exc, what)}") from None
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise ConfigError(f"{path}: a {what} must be a mapping of keys, got {type(raw).__name__}")
    return raw


def _refused(exc: ConfigError, what: str) -> str:
    """A parse_text error worded for a file: parse errors as they are, bounds as refusals."""
    message = str(exc)
    if message.startswith("not valid "):
        return message
    if message == "nested too deeply to be a config":
        return f"{what} {message}"
    return f"{what} refused: {message}"


def load_model(path: str | Path, model: type[M], *, what: str = "config file") -> M:
    """Read `path` with `load_mapping` and validate it as `model`.

    Raises:
        ConfigError: `path: key.path: message`, naming the first bad key.
    """
    return validate_mapping(path, load_mapping(path, what=what), model, what=what)


def validate_mapping(path: str | Path, raw: Any, model: type[M], *, what: str = "config file") -> M:
    """Validate data read from `path` as `model`; ConfigError `path: key.path: message`."""
    try:
        return model.model_validate(raw)
    except ConfigError as exc:
        detail = str(exc).removeprefix(f"invalid {model.__name__}: ")
        raise ConfigError(f"{path}: {detail}", key_path=exc.key_path, detail=exc.detail) from None
    except RecursionError:
        raise ConfigError(f"{path}: {what} nested too deeply to be a config") from None
