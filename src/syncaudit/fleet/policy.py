"""The gate policy: which checks judge each camera, LiDAR, log and calibration, and their limits.

A policy is YAML validated by pydantic (`schemas/policy.schema.json` is its JSON schema).
Checks have a `min` and/or `max` and a `severity` (`fail` or `warn`); `defaults` apply to
every log, `cameras.<name>` to that camera on every vehicle, `vehicles.<id>` (with its own
`cameras.<name>`) to one vehicle. Later levels override single fields of a check
(`{max: 300}` keeps the severity), and `{enabled: false}` switches a check off.
"""

from __future__ import annotations

import difflib
import hashlib
import json
import re
import types
import typing
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from syncaudit.config import kind_of, parse_text, read_text
from syncaudit.errors import ConfigError

Severity = Literal["fail", "warn"]
POLICY_VERSION: Literal[1] = 1


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Limit(_Strict):
    """A numeric check: the measured value must lie within [min, max] (either may be omitted)."""

    min: float | None = Field(None, allow_inf_nan=False)
    max: float | None = Field(None, allow_inf_nan=False)
    severity: Severity = "fail"
    enabled: bool = True

    @model_validator(mode="after")
    def _ordered(self) -> Limit:
        for name, bound in (("min", self.min), ("max", self.max)):
            if bound is not None and bound < 0:
                raise ValueError(
                    f"{name} {bound:g} is negative: every check measures a quantity >= 0"
                )
        if self.min is not None and self.max is not None and self.min > self.max:
            raise ValueError(f"min ({self.min}) is above max ({self.max})")
        return self


class Flag(_Strict):
    """A yes/no check: the measured flag must equal `expect`."""

    expect: bool = True
    severity: Severity = "fail"
    enabled: bool = True


class TopicsCheck(_Strict):
    """The log must hold every topic listed."""

    topics: list[str] = Field(default_factory=list)
    severity: Severity = "fail"
    enabled: bool = True


class Condition(_Strict):
    """A condition of the log file that must not be present (a cut-off log, no index)."""

    severity: Severity = "fail"
    enabled: bool = True


class CameraChecks(_Strict):
    """Checks of one camera's audit (times in microseconds, variances in us^2)."""

    error_mean_us: Limit | None = Limit(max=250.0)
    """Eq. 5 over the whole log: mean |error|."""
    error_var_us2: Limit | None = Limit(max=40_000.0)
    """Eq. 6 over the whole log: variance of |error|."""
    error_p99_us: Limit | None = None
    error_max_us: Limit | None = None
    paired_fraction: Limit | None = Limit(min=0.5)
    """Frames paired with a LiDAR revolution over all frames."""
    delay_mismatch_us: Limit | None = None
    """|recommended - applied| trigger delay."""
    t1_p99_us: Limit | None = None
    t2_p99_us: Limit | None = None
    t3_p99_us: Limit | None = None
    t4_p99_us: Limit | None = None


class LidarChecks(_Strict):
    """Checks of the triggering LiDAR."""

    clock_synchronised: Flag | None = Flag(severity="warn")
    drop_rate: Limit | None = None
    """Dropped packets over expected packets (0..1)."""
    rpm: Limit | None = None
    packets_per_revolution: Limit | None = None


class LogChecks(_Strict):
    """Checks of the log as a whole."""

    required_topics: TopicsCheck | None = None
    duration_s: Limit | None = None
    truncated: Condition | None = Condition(severity="fail")
    """The file is cut off (or a chunk of it cut or damaged): only what precedes was read."""
    damaged_messages: Limit | None = Limit(max=0, severity="warn")
    """Messages skipped because their bytes did not decode, over all topics."""
    missing_index: Condition | None = Condition(severity="warn")
    """The index (MCAP summary, ROS 1 index records) is missing: the file was read linearly."""


class CalibrationChecks(_Strict):
    """Calibrated vs recorded extrinsics; run only when the log holds two or more point clouds.

    Off by default: the calibration costs a few CPU seconds per session (the sync audit of
    a small log costs tens of ms), so a policy switches it on by writing a limit.
    """

    rotation_deg: Limit | None = None
    translation_cm: Limit | None = None

    @property
    def enabled(self) -> bool:
        """Some calibration check is on (so the worker calibrates logs with the scans)."""
        return any(
            limit is not None and limit.enabled
            for limit in (self.rotation_deg, self.translation_cm)
        )


class CheckSet(_Strict):
    """Every check group; the level at which they apply is set by where the set appears."""

    camera: CameraChecks = CameraChecks()
    lidar: LidarChecks = LidarChecks()
    log: LogChecks = LogChecks()
    calibration: CalibrationChecks = CalibrationChecks()


class Override(_Strict):
    """Checks for one vehicle; only the fields written (at any depth) replace the defaults."""

    camera: CameraChecks = CameraChecks()
    lidar: LidarChecks = LidarChecks()
    log: LogChecks = LogChecks()
    calibration: CalibrationChecks = CalibrationChecks()
    cameras: dict[str, CameraChecks] = Field(default_factory=dict)
    """Per camera name, camera checks for this vehicle (fields written only)."""


class Policy(_Strict):
    """A whole gate policy."""

    version: Literal[1] = POLICY_VERSION
    description: str | None = None
    vehicle_pattern: str | None = None
    """Regex searched in the log path; its named group `vehicle` is the vehicle id."""
    rigs: dict[str, str] = Field(default_factory=dict)
    """Rig file per vehicle id (relative paths are relative to the policy file)."""
    default_rig: str | None = None
    """Rig file for logs with no rig beside them, in the manifest, or under `rigs`."""
    defaults: CheckSet = CheckSet()
    cameras: dict[str, CameraChecks] = Field(default_factory=dict)
    """Per camera name (every vehicle), camera checks (fields written only)."""
    vehicles: dict[str, Override] = Field(default_factory=dict)

    @field_validator("vehicle_pattern")
    @classmethod
    def _pattern(cls, value: str | None) -> str | None:
        if value is None:
            return value
        try:
            compiled = re.compile(value)
        except re.error as exc:
            raise ValueError(f"not a valid regular expression: {exc}") from exc
        if "vehicle" not in compiled.groupindex:
            raise ValueError("needs a named group (?P<vehicle>...)")
        return value

    @model_validator(mode="after")
    def _overrides_valid(self) -> Policy:
        # Validate every partial override against the full models now, so a bad key in
        # an override is reported at load time with its place in the file.
        for name, partial in self.cameras.items():
            _merge_model(CameraChecks, CameraChecks(), partial, f"cameras.{name}")
        for vid, override in self.vehicles.items():
            for group, model in _GROUPS.items():
                base = getattr(self.defaults, group)
                _merge_model(model, base, getattr(override, group), f"vehicles.{vid}.{group}")
            for name, partial in override.cameras.items():
                _merge_model(
                    CameraChecks, CameraChecks(), partial, f"vehicles.{vid}.cameras.{name}"
                )
        return self

    def checks_for(self, vehicle: str | None, camera: str | None = None) -> CheckSet:
        """The checks that apply to one vehicle (and camera), overrides merged in order."""
        groups: dict[str, BaseModel] = {g: getattr(self.defaults, g) for g in _GROUPS}
        if camera is not None and camera in self.cameras:
            groups["camera"] = _merge_model(
                CameraChecks, groups["camera"], self.cameras[camera], ""
            )
        override = self.vehicles.get(vehicle) if vehicle is not None else None
        if override is not None:
            for group, model in _GROUPS.items():
                groups[group] = _merge_model(model, groups[group], getattr(override, group), "")
            if camera is not None and camera in override.cameras:
                groups["camera"] = _merge_model(
                    CameraChecks, groups["camera"], override.cameras[camera], ""
                )
        return CheckSet.model_validate({g: m.model_dump() for g, m in groups.items()})

    def uses_vehicles(self) -> bool:
        """Whether verdicts depend on the vehicle id (a pattern, per-vehicle rigs or checks)."""
        return bool(self.vehicle_pattern or self.rigs or self.vehicles)

    def calibrates(self) -> bool:
        """Whether any vehicle (or the defaults) has a calibration check switched on."""
        return self.defaults.calibration.enabled or any(
            self.checks_for(vehicle).calibration.enabled for vehicle in self.vehicles
        )

    def fingerprint(self) -> str:
        """A short hash of the policy's content (not its formatting), stored with each verdict."""
        text = json.dumps(_written(self), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()[:16]


_GROUPS: dict[str, type[BaseModel]] = {
    "camera": CameraChecks,
    "lidar": LidarChecks,
    "log": LogChecks,
    "calibration": CalibrationChecks,
}


def _merge_model(
    model: type[BaseModel], base: BaseModel, override: BaseModel, where: str
) -> BaseModel:
    """`base` with the fields written in `override` merged check by check and field by
    field; ValueError naming `where` when the result is inconsistent (min above max)."""
    merged = base.model_dump()
    partial = override.model_dump(exclude_unset=True)
    for key, value in partial.items():
        if key not in model.model_fields:
            raise ValueError(
                f"{where}.{key}: unknown check (known: {', '.join(model.model_fields)})"
            )
        if value is None or merged.get(key) is None or not isinstance(value, dict):
            merged[key] = value
        else:
            merged[key] = {**merged[key], **value}
    try:
        return model.model_validate(merged)
    except ValidationError as exc:
        lines = [
            f"{where}.{_loc(e['loc'])}: {str(e['msg']).removeprefix('Value error, ')}"
            for e in exc.errors()
        ]
        raise ValueError("; ".join(lines)) from exc


def _loc(loc: tuple[Any, ...]) -> str:
    return ".".join(str(part) for part in loc) or "(top level)"


def _known_at(loc: tuple[Any, ...]) -> list[str]:
    """The keys a policy mapping at `loc` (the parent of an unknown key) may hold."""
    model: type[BaseModel] | None = Policy
    parts = list(loc)
    while parts and model is not None:
        field = model.model_fields.get(str(parts.pop(0)))
        if field is None:
            return []
        inner = field.annotation
        if typing.get_origin(inner) in (typing.Union, types.UnionType):  # X | None
            inner = next(a for a in typing.get_args(inner) if a is not type(None))
        if typing.get_origin(inner) is dict:  # a name (vehicle, camera) comes first
            if parts:
                parts.pop(0)
            inner = typing.get_args(inner)[1]
        model = inner if isinstance(inner, type) and issubclass(inner, BaseModel) else None
    return sorted(model.model_fields) if model is not None else []


def _did_you_mean(loc: tuple[Any, ...]) -> str:
    """` (did you mean 'x'?)` for an unknown key near a known one, else the known keys."""
    known = _known_at(tuple(loc[:-1]))
    close = difflib.get_close_matches(str(loc[-1]), known, n=1, cutoff=0.6)
    if close:
        return f" (did you mean {close[0]!r}?)"
    return f" (known: {', '.join(known)})" if known else ""


def policy_errors(exc: ValidationError) -> list[str]:
    """One line per bad key: `where: message`."""
    lines = []
    for error in exc.errors():
        message = " ".join(str(error["msg"]).split()).removeprefix("Value error, ")
        if error["type"] == "extra_forbidden":
            message = "unknown key" + _did_you_mean(error["loc"])
        where = _loc(error["loc"])
        lines.append(
            message if message.startswith(("cameras.", "vehicles.")) else f"{where}: {message}"
        )
    return lines


def parse_policy(raw: object, source: str) -> Policy:
    """Validate a policy mapping; ConfigError listing every bad key, one per line."""
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise ConfigError(f"{source}: a policy must be a mapping (got {type(raw).__name__})")
    try:
        return Policy.model_validate(raw)
    except ValidationError as exc:
        lines = policy_errors(exc)
        raise ConfigError("\n".join(f"{source}: {line}" for line in lines)) from exc


def load_policy(path: str | Path) -> Policy:
    """Read and validate a policy YAML/JSON file; rig paths become relative to its folder."""
    path = Path(path)
    text = read_text(path, what="policy file")
    try:
        raw = parse_text(text, kind_of(path))  # bounded: aliases, size, depth, duplicate keys
    except ConfigError as exc:
        message = str(exc)
        prefix = "" if message.startswith("not valid") else "policy file refused: "
        raise ConfigError(f"{path}: {prefix}{message}") from None
    policy = parse_policy(raw, str(path))
    base = path.resolve().parent
    rigs = {vid: str(base / rig) for vid, rig in policy.rigs.items()}
    default_rig = str(base / policy.default_rig) if policy.default_rig else None
    return policy.model_copy(update={"rigs": rigs, "default_rig": default_rig})


def policy_json_schema() -> dict[str, Any]:
    """The JSON schema of policy files, as exported to schemas/policy.schema.json."""
    schema = Policy.model_json_schema()
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "syncaudit gate policy"
    return schema


def _written(policy: Policy) -> dict[str, Any]:
    """The policy as data: `defaults` in full, overrides only as written."""
    data = policy.model_dump(mode="json")
    data["cameras"] = {
        name: checks.model_dump(mode="json", exclude_unset=True)
        for name, checks in policy.cameras.items()
    }
    data["vehicles"] = {
        vid: override.model_dump(mode="json", exclude_unset=True)
        for vid, override in policy.vehicles.items()
    }
    return data


def _clean(node: Any, depth: int = 0) -> Any:
    """Drop unset limit bounds and `enabled: true` noise; keep `null` checks (= off)."""
    if isinstance(node, dict):
        out = {}
        for key, value in node.items():
            if isinstance(value, dict) and set(value) >= {"severity", "enabled"}:
                value = {
                    k: v for k, v in value.items() if v is not None and not (k == "enabled" and v)
                }
            elif value is None and depth == 0:
                continue
            out[key] = _clean(value, depth + 1)
        return out
    return node


def policy_to_yaml(policy: Policy, header: str = "") -> str:
    """The policy as YAML text (`null` marks a check switched off)."""
    data = _clean(_written(policy))
    body = yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=100)
    return header + body
