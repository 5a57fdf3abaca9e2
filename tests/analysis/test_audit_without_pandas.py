"""The audit and its JSON need no pandas (~0.2 s of start-up); the per-frame DataFrame is
built, identical, only when an output asks for it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

SAMPLE = Path(__file__).resolve().parents[2] / "sample_logs" / "vlp16_three_cameras.mcap"

SCRIPT = """
import json, sys
from syncaudit.audit.run import audit_log
from syncaudit.rig import load_rig

result = audit_log(sys.argv[1], load_rig(sys.argv[1] + ".rig.yaml"), jobs=1)
json.dumps(result.to_dict())
print("pandas" in sys.modules, "pyarrow" in sys.modules)
frames = result.frames()
print(len(frames), str(frames["t_l_ns"].dtype), str(frames["camera"].dtype))
"""


def test_json_audit_does_not_import_pandas() -> None:
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(SAMPLE)], capture_output=True, text=True, check=True
    )
    imported, frames = done.stdout.splitlines()
    assert imported == "False False"
    rows, stamp_dtype, camera_dtype = frames.split()
    assert int(rows) > 0 and stamp_dtype == "Int64" and camera_dtype.startswith("str")
