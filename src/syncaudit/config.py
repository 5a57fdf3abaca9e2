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

from syncaudit.errors import ConfigError

MAX_CONFIG_BYTES = 1 << 20
"""Largest config file read (1 MiB): a rig of a thousand cameras is about 200 KB."""

MAX_NESTING = 100
"""Deepest nesting of mappings and lists accepted in a config file (rigs use 4)."""

_BOMS: tuple[tuple[bytes, str], ...] = (
    (b"\xff\xfe\x00\x00", "utf-32-le"),
    (b"\x00\x00\xfe\xff", "utf-32-be"),
    (b"\xef\xbb\xbf", "utf-8-sig"),
    (b"\xff\xfe", "utf-16-le"),
    (b"\xfe\xff", "utf-16-be"),
)

M = TypeVar("M", bound="ConfigModel")

_YAML_LOADER: type[yaml.SafeLoader] = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
"""libyaml's safe loader where PyYAML has it (3-4x faster on a big rig; it refuses nesting
past 1000 levels itself), else the pure-Python one."""

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


def read_text(path: Path, *, what: str = "config file") -> str:
    """A config file's text: size-capped, UTF-8 or UTF-16/32 with a byte-order mark.

    Raises:
        ConfigError: unreadable, larger than MAX_CONFIG_BYTES, or not text.
    """
    try:
        with path.open("rb") as handle:
            data = handle.read(MAX_CONFIG_BYTES + 1)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read {what} ({exc.strerror or exc})") from None
    if len(data) > MAX_CONFIG_BYTES:
        raise ConfigError(
            f"{path}: {what} larger than {MAX_CONFIG_BYTES // 1024} KiB; refusing to read it"
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


def _depth(value: Any) -> int:
    """Nesting depth of parsed data, without recursion."""
    deepest = 0
    stack: list[tuple[Any, int]] = [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, dict):
            deepest = max(deepest, depth)
            stack.extend((child, depth + 1) for child in item.values())
        elif isinstance(item, list):
            deepest = max(deepest, depth)
            stack.extend((child, depth + 1) for child in item)
    return deepest


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


def load_mapping(path: str | Path, *, what: str = "config file") -> dict[str, Any]:
    """Parse a YAML (.yaml/.yml/other), TOML (.toml) or JSON (.json) file into a dict.

    Raises:
        ConfigError: naming the file, for anything but a readable mapping of bounded
            size and nesting.
    """
    path = Path(path)
    text = read_text(path, what=what)
    suffix = path.suffix.lower()
    kind = {".toml": "TOML", ".json": "JSON"}.get(suffix, "YAML")
    try:
        if kind == "TOML":
            raw: Any = tomllib.loads(text)
        elif kind == "JSON":
            raw = json.loads(text)
        else:
            raw = yaml.load(text, Loader=_YAML_LOADER)
    except RecursionError:
        raise ConfigError(f"{path}: {what} nested too deeply to be a config") from None
    except (yaml.YAMLError, tomllib.TOMLDecodeError, ValueError) as exc:
        raise ConfigError(f"{path}: not valid {kind}: {_parse_error(exc)}") from None
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise ConfigError(f"{path}: a {what} must be a mapping of keys, got {type(raw).__name__}")
    if _depth(raw) > MAX_NESTING:
        raise ConfigError(f"{path}: {what} nested deeper than {MAX_NESTING} levels")
    return raw


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
