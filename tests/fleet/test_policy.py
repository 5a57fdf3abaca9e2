"""Policy files: the schema on disk, overrides, one clear error per bad key, --init margins."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest
import yaml

from syncaudit.errors import ConfigError, InputOpenError
from syncaudit.fleet.init_policy import init_policy_yaml, policy_from_outcomes
from syncaudit.fleet.job import LogOutcome
from syncaudit.fleet.policy import load_policy, parse_policy, policy_json_schema

REPO = Path(__file__).resolve().parents[2]


def test_policy_schema_file_is_the_models_schema() -> None:
    on_disk = json.loads((REPO / "schemas" / "policy.schema.json").read_text())
    assert on_disk == policy_json_schema(), "regenerate schemas/policy.schema.json"


def test_overrides_merge_field_by_field_in_order() -> None:
    policy = parse_policy(
        {
            "defaults": {"camera": {"error_mean_us": {"max": 200, "severity": "warn"}}},
            "cameras": {"front": {"error_mean_us": {"max": 300}}},
            "vehicles": {
                "car1": {
                    "camera": {"error_p99_us": {"max": 900}},
                    "cameras": {"front": {"error_mean_us": {"max": 400, "severity": "fail"}}},
                    "lidar": {"clock_synchronised": {"enabled": False}},
                }
            },
        },
        "p.yaml",
    )
    rear = policy.checks_for("car2", "rear").camera.error_mean_us
    assert rear is not None and (rear.max, rear.severity) == (200, "warn")
    front = policy.checks_for("car2", "front").camera.error_mean_us
    assert front is not None and (front.max, front.severity) == (300, "warn")  # severity kept
    car1 = policy.checks_for("car1", "front")
    assert car1.camera.error_mean_us is not None
    assert (car1.camera.error_mean_us.max, car1.camera.error_mean_us.severity) == (400, "fail")
    assert car1.camera.error_p99_us is not None and car1.camera.error_p99_us.max == 900
    assert car1.lidar.clock_synchronised is not None and not car1.lidar.clock_synchronised.enabled
    assert policy.checks_for("car2").lidar.clock_synchronised.enabled  # type: ignore[union-attr]


@pytest.mark.parametrize(
    ("raw", "lines"),
    [
        (
            {"defaults": {"camera": {"eror_mean_us": {"max": 1}}}},
            ["defaults.camera.eror_mean_us: unknown key (did you mean 'error_mean_us'?)"],
        ),
        (  # issue 23: as strictly as the rig: a negative limit, a misspelt key's neighbour
            {"defaults": {"camera": {"error_mean_us": {"max": -5}}}},
            ["defaults.camera.error_mean_us: max -5 is negative"],
        ),
        (
            {"vehicles": {"car1": {"cameras": {"front": {"error_mean_us": {"mx": 3}}}}}},
            ["vehicles.car1.cameras.front.error_mean_us.mx: unknown key (did you mean 'max'?)"],
        ),
        (
            {"defaults": {"log": {"truncted": {"severity": "warn"}}}},
            ["defaults.log.truncted: unknown key (did you mean 'truncated'?)"],
        ),
        (
            {"defaults": {"camera": {"error_mean_us": {"max": "x", "sev": "fail"}}}},
            [
                "defaults.camera.error_mean_us.max: Input should be a valid number",
                "defaults.camera.error_mean_us.sev: unknown key",
            ],
        ),
        (
            {"defaults": {"lidar": {"rpm": {"min": 700, "max": 500}}}},
            ["defaults.lidar.rpm: min (700.0) is above max (500.0)"],
        ),
        (
            {"defaults": {"camera": {"error_mean_us": {"max": 1, "severity": "error"}}}},
            ["defaults.camera.error_mean_us.severity:"],
        ),
        (
            {"vehicles": {"car1": {"cameras": {"front": {"nope": {}}}}}},
            ["vehicles.car1.cameras.front.nope: unknown key"],
        ),
        (
            {
                "defaults": {"lidar": {"rpm": {"max": 500}}},
                "vehicles": {"car1": {"lidar": {"rpm": {"min": 700}}}},
            },
            ["vehicles.car1.lidar.rpm: min (700.0) is above max (500.0)"],
        ),
        (
            {"vehicle_pattern": "cars/([^/]+)/"},
            ["vehicle_pattern: needs a named group (?P<vehicle>...)"],
        ),
        (
            {"defaults": {"camera": {"error_mean_us": {"max": float("nan")}}}},
            ["defaults.camera.error_mean_us.max:"],
        ),
    ],
)
def test_each_bad_key_gets_one_clear_line(raw: dict[str, object], lines: list[str]) -> None:
    with pytest.raises(ConfigError) as caught:
        parse_policy(raw, "p.yaml")
    got = str(caught.value).splitlines()
    assert len(got) == len(lines), got
    for line, want in zip(got, lines, strict=True):
        assert line.startswith(f"p.yaml: {want}"), line
    assert caught.value.exit_code == 6


def test_unreadable_and_non_mapping_policy_files(tmp_path: Path) -> None:
    bad = tmp_path / "p.yaml"
    bad.write_text("defaults: [\n")
    with pytest.raises(ConfigError, match=r"p.yaml: not valid YAML"):
        load_policy(bad)
    bad.write_text("- 1\n")
    with pytest.raises(ConfigError, match="must be a mapping"):
        load_policy(bad)
    with pytest.raises(InputOpenError, match="cannot read policy"):  # exit 2, as any missing input
        load_policy(tmp_path / "absent.yaml")


def test_init_policy_passes_its_logs_with_the_documented_margins(
    three_cameras_outcome: LogOutcome, tmp_path: Path
) -> None:
    from syncaudit.fleet.checks import evaluate

    text = init_policy_yaml([three_cameras_outcome])
    path = tmp_path / "policy.yaml"
    path.write_text(text)
    schema = json.loads((REPO / "schemas" / "policy.schema.json").read_text())
    jsonschema.validate(yaml.safe_load(text), schema)
    policy = load_policy(path)
    assert policy == policy_from_outcomes([three_cameras_outcome]).model_copy(
        update={"rigs": {}, "default_rig": None}
    )
    front = next(c for c in three_cameras_outcome.audit["cameras"] if c["camera"] == "front")  # type: ignore[index]
    limit = policy.checks_for(None, "front").camera.error_mean_us
    assert limit is not None and limit.max == round(front["error_mean_us"] * 1.5 + 50, 1)
    var = policy.checks_for(None, "front").camera.error_var_us2
    assert var is not None and var.max == round(front["error_var_us2"] * 2.25 + 2500, 1)
    checks = evaluate(three_cameras_outcome, policy, None)
    assert checks and all(c.passed for c in checks), [c for c in checks if not c.passed]
    topics = policy.defaults.log.required_topics
    assert topics is not None and "/velodyne_packets" in topics.topics


def test_the_documented_example_policy_is_valid() -> None:
    docs = (REPO / "docs" / "fleet.md").read_text()
    example = docs.split("```yaml\n", 1)[1].split("\n```", 1)[0]
    raw = yaml.safe_load(example)
    jsonschema.validate(raw, json.loads((REPO / "schemas" / "policy.schema.json").read_text()))
    policy = parse_policy(raw, "docs/fleet.md")
    rear = policy.checks_for("car7", "rear")
    assert rear.camera.error_mean_us is not None and rear.camera.error_mean_us.max == 400
    assert rear.camera.t2_p99_us is not None and rear.camera.t2_p99_us.severity == "warn"
    assert rear.lidar.clock_synchronised is not None and not rear.lidar.clock_synchronised.enabled
    front = policy.checks_for("car1", "front")
    assert front.camera.error_mean_us is not None and front.camera.error_mean_us.max == 200
