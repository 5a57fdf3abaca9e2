"""Config files: one loader and one strict base for rigs, calibration configs and simulators."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from syncaudit.calib.settings import CalibConfig, load_config
from syncaudit.config import MAX_CONFIG_BYTES, load_mapping
from syncaudit.errors import ConfigError
from syncaudit.rig import load_rig

RIG = "lidar:\n  topic: /velodyne_packets\n"


def _rig(tmp_path: Path, text: str, name: str = "rig.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("body", "key"),
    [
        ("thresholds:\n  error_mean_us: 1e308\n", "thresholds.error_mean_us"),
        ("thresholds:\n  error_mean_us: .inf\n", "thresholds.error_mean_us"),
        ("thresholds:\n  error_var_us2: .nan\n", "thresholds.error_var_us2"),
        ("analysis:\n  clock_sync_tolerance_ms: 1e308\n", "analysis.clock_sync_tolerance_ms"),
        ("analysis:\n  assumed_t2_us: .inf\n", "analysis.assumed_t2_us"),
        ("cameras:\n  - name: a\n    yaw_deg: .nan\n", "cameras.0.yaw_deg"),
        ("cameras:\n  - name: a\n    yaw_deg: .inf\n", "cameras.0.yaw_deg"),
        ("cameras:\n  - name: a\n    yaw_deg: 1e308\n", "cameras.0.yaw_deg"),
        ("cameras:\n  - name: a\n    azimuth_deg: 360\n", "cameras.0.azimuth_deg"),
        (
            "cameras:\n  - name: a\n    assumed_exposure_us: 1e308\n",
            "cameras.0.assumed_exposure_us",
        ),
    ],
)
def test_rig_numbers_are_finite_and_ranged(tmp_path: Path, body: str, key: str) -> None:
    with pytest.raises(ConfigError, match=rf"rig.yaml: {key}:"):
        load_rig(_rig(tmp_path, RIG + body))


def test_lidar_azimuths_are_ranged(tmp_path: Path) -> None:
    for value in (".nan", "360", "-1"):
        text = f"lidar:\n  topic: /v\n  azimuth_of_x_axis_deg: {value}\n"
        with pytest.raises(ConfigError, match=r"lidar\.azimuth_of_x_axis_deg"):
            load_rig(_rig(tmp_path, text))


def test_typo_names_the_nearest_key(tmp_path: Path) -> None:
    text = RIG + "cameras:\n  - name: a\n    imag_topic: /a\n"
    with pytest.raises(
        ConfigError, match=r"imag_topic: unknown key \(did you mean 'image_topic'\?\)"
    ):
        load_rig(_rig(tmp_path, text))
    with pytest.raises(ConfigError, match=r"thresholds.error_mean: unknown key \(did you mean"):
        load_rig(_rig(tmp_path, RIG + "thresholds:\n  error_mean: 3\n"))


def test_encodings(tmp_path: Path) -> None:
    utf16 = tmp_path / "utf16.yaml"
    utf16.write_bytes(RIG.encode("utf-16"))  # with its byte-order mark
    assert load_rig(utf16).lidar.topic == "/velodyne_packets"
    bom8 = tmp_path / "bom8.yaml"
    bom8.write_bytes(b"\xef\xbb\xbf" + RIG.encode())
    assert load_rig(bom8).lidar.topic == "/velodyne_packets"
    latin1 = tmp_path / "latin1.yaml"
    latin1.write_bytes(RIG.encode() + "# caf\xe9\n".encode("latin-1"))
    with pytest.raises(ConfigError, match=r"not UTF-8 text \(byte 0xe9 at offset \d+\)"):
        load_rig(latin1)
    bare16 = tmp_path / "bare16.yaml"
    bare16.write_bytes(RIG.encode("utf-16-le"))  # no mark: refused, not guessed
    with pytest.raises(ConfigError, match="NUL bytes"):
        load_rig(bare16)


def test_deep_nesting_and_size_are_bounded(tmp_path: Path) -> None:
    deep_yaml = _rig(tmp_path, "lidar: " + "[" * 5_000 + "]" * 5_000 + "\n", "deep.yaml")
    deep_json = _rig(tmp_path, '{"lidar": ' + "[" * 100_000 + "]" * 100_000 + "}", "deep.json")
    for path in (deep_yaml, deep_json):
        with pytest.raises(ConfigError, match="nested"):
            load_rig(path)
    big = tmp_path / "big.yaml"
    big.write_text(RIG + "#" * MAX_CONFIG_BYTES)
    started = time.process_time()  # CPU time: the work done, not the machine's load
    with pytest.raises(ConfigError, match="larger than 1024 KiB"):
        load_rig(big)
    assert time.process_time() - started < 1.0


def test_not_a_mapping_and_missing_lidar(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="must be a mapping"):
        load_mapping(_rig(tmp_path, "- 1\n- 2\n"))
    with pytest.raises(ConfigError, match="needs a 'lidar' mapping"):
        load_rig(_rig(tmp_path, "cameras: []\n"))


def test_toml_and_json_rigs(tmp_path: Path) -> None:
    toml = _rig(tmp_path, '[lidar]\ntopic = "/v"\n', "rig.toml")
    as_json = _rig(tmp_path, json.dumps({"lidar": {"topic": "/v"}}), "rig.json")
    assert load_rig(toml) == load_rig(as_json)


def test_calib_config_file_names_the_key(tmp_path: Path) -> None:
    path = _rig(tmp_path, "selection:\n  min_stops: 1\n", "calib.yaml")
    with pytest.raises(ConfigError, match=r"calib.yaml: selection.min_stops:"):
        load_config(path, CalibConfig)
    path = _rig(tmp_path, "registration:\n  voxel_m: .inf\n", "calib2.yaml")
    with pytest.raises(ConfigError, match=r"registration.voxel_m"):
        load_config(path, CalibConfig)


def test_many_camera_rig_validates_in_linear_time(tmp_path: Path) -> None:
    """Validation of a rig is linear in its cameras (20,000 cameras well under a second)."""

    def rig(n: int) -> Path:
        cams = "".join(f"  - name: c{i}\n    image_topic: /c{i}/image\n" for i in range(n))
        return _rig(tmp_path, RIG + "cameras:\n" + cams, f"rig{n}.yaml")

    small, large = rig(500), rig(5_000)
    timings = []
    for path in (small, large):
        # CPU time, best of three: other processes on a loaded machine cannot inflate it.
        runs = []
        for _ in range(3):
            started = time.process_time()
            assert len(load_rig(path).cameras) in (500, 5_000)
            runs.append(time.process_time() - started)
        timings.append(min(runs))
    assert timings[1] < 30 * timings[0] + 0.5  # 10x the cameras: about 10x the time


def test_a_config_error_keeps_where_and_what(tmp_path: Path) -> None:
    """The key path and the message apart, so a command can name the option behind a key."""
    rig = _rig(
        tmp_path,
        "lidar: {topic: /l}\ncameras:\n- {name: front, image_topic: /i, stamp: exposure_begin}\n",
    )
    with pytest.raises(ConfigError) as caught:
        load_rig(rig)
    assert caught.value.key_path == ("cameras", 0, "stamp")
    assert caught.value.detail is not None and caught.value.detail.startswith("Input should be")
    assert str(caught.value) == f"{rig}: cameras.0.stamp: {caught.value.detail}"
