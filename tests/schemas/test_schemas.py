"""The JSON schemas in schemas/ describe what the code reads and writes now."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema

from syncaudit.audit.run import audit_log
from syncaudit.rig import load_rig, rig_json_schema

SCHEMAS = Path(__file__).resolve().parents[2] / "schemas"
SAMPLES = Path(__file__).resolve().parents[2] / "sample_logs"


def test_rig_schema_file_is_the_models_schema() -> None:
    on_disk = json.loads((SCHEMAS / "rig.schema.json").read_text())
    assert on_disk == rig_json_schema(), "regenerate schemas/rig.schema.json from rig_json_schema()"


def test_sample_rig_files_validate_against_the_rig_schema() -> None:
    schema = json.loads((SCHEMAS / "rig.schema.json").read_text())
    import yaml

    for rig_file in sorted(SAMPLES.glob("*.rig.yaml")):
        jsonschema.validate(yaml.safe_load(rig_file.read_text()), schema)


def test_audit_json_validates_against_the_audit_schema() -> None:
    schema = json.loads((SCHEMAS / "audit.schema.json").read_text())
    for name in ("vlp16_short.bag", "pandar40p_adaptive.mcap"):
        log = SAMPLES / name
        result = audit_log(log, load_rig(f"{log}.rig.yaml"), jobs=1).to_dict()
        jsonschema.validate(result, schema)
        assert result["cameras"], name
