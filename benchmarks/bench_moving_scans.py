#!/usr/bin/env python
"""Moving scans in the calibration: the same sessions calibrated without them, with the
default data-driven choice, and with them always (`MovingScansConfig.use`).

Sessions with short stops and wide turns, where most scans are taken while moving (the
issue's case), plus any matrix case of `bench_calib.py` (`--cases`). For each session and
mode it prints the calibrated extrinsic's error against the simulator's truth, the CPU
seconds of `calibrate_log`, and how many moving scans each LiDAR had and used.

    python benchmarks/bench_moving_scans.py --seeds 2
    python benchmarks/bench_moving_scans.py --no-short --cases parking-64-facing-bumper

Needs the `calib` extra (`pip install -e '.[calib]'`).
"""

from __future__ import annotations

import argparse
import json
import resource
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from syncaudit.calib import CalibConfig, calibrate_log, se3
from syncaudit.calib.settings import MovingScansConfig
from syncaudit.simulate.calib_config import CalibSceneConfig, calib_scene_config
from syncaudit.simulate.calib_session import MATRIX, simulate_calib_session, truth_path

SHORT_STOPS: dict[str, tuple[dict[str, Any], dict[str, Any]]] = {
    "short-16-wide-turns": (
        {"beams": 16, "motion": "drive", "n_stops": 5, "mount": "roof_left_right"},
        {"turn_deg_range": (70.0, 85.0), "stop_duration_s_range": (0.2, 0.3)},
    ),
    "short-32-wide-turns": (
        {"beams": 32, "motion": "drive", "n_stops": 6, "mount": "roof_left_right"},
        {"turn_deg_range": (70.0, 85.0), "stop_duration_s_range": (0.2, 0.3)},
    ),
    "short-32-fast": (
        {"beams": 32, "motion": "drive", "n_stops": 8, "mount": "roof_front_rear"},
        {"stop_duration_s_range": (0.2, 0.24), "moving_scans_range": (4, 6)},
    ),
}
"""Short-stop sessions: (`calib_scene_config` arguments, `CalibSceneConfig` overrides)."""
MODES = ("never", "auto", "always")


def _cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def _config(name: str, seed: int) -> CalibSceneConfig:
    if name in SHORT_STOPS:
        args, overrides = SHORT_STOPS[name]
        return calib_scene_config(seed=seed, **args).model_copy(update=overrides)
    return calib_scene_config(seed=seed, **{"n_stops": 12, **MATRIX[name]})


def _row(path: Path, mode: str) -> dict[str, Any]:
    truth = json.loads(truth_path(path).read_text())
    cpu0 = _cpu_s()
    result = calibrate_log(path, CalibConfig(moving_scans=MovingScansConfig(use=mode)))
    cpu = _cpu_s() - cpu0
    row: dict[str, Any] = {"mode": mode, "cpu_s": cpu, "rot_deg": None, "trans_cm": None}
    row["moving"] = [
        (m.seen, m.used) if (m := lidar.moving_scans) is not None else (0, 0)
        for lidar in result.lidars
    ]
    ext = result.extrinsics[0]
    if ext.result is not None:
        lidar = next(x for x in truth["lidars"] if x["topic"] == ext.topic)
        true = np.array(lidar[f"true_{truth['reference_lidar']}_from_lidar"]["matrix"])
        rot_deg, trans_m = se3.transform_difference(true, np.array(ext.result.matrix))
        row["rot_deg"], row["trans_cm"] = rot_deg, trans_m * 100.0
    else:
        row["reason"] = result.reason
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--first-seed", type=int, default=0, help="seeds K..K+N-1")
    parser.add_argument("--cases", nargs="*", default=[], choices=list(MATRIX))
    parser.add_argument("--no-short", action="store_true", help="leave out the short-stop sessions")
    parser.add_argument("--modes", nargs="+", default=list(MODES), choices=list(MODES))
    args = parser.parse_args(argv)
    names = ([] if args.no_short else list(SHORT_STOPS)) + list(args.cases)
    print(
        f"{'session':24s} {'seed':>4s} {'mode':>6s} {'rot deg':>8s} {'cm':>7s} {'cpu s':>6s}  "
        "moving scans (seen, used) per LiDAR"
    )
    with tempfile.TemporaryDirectory(prefix="bench_moving_") as tmp:
        for name in names:
            for seed in range(args.first_seed, args.first_seed + args.seeds):
                path = Path(tmp) / f"{name}_s{seed}.mcap"
                simulate_calib_session(path, _config(name, seed))
                for mode in args.modes:
                    row = _row(path, mode)
                    err = (
                        f"{row['rot_deg']:8.4f} {row['trans_cm']:7.3f}"
                        if row["rot_deg"] is not None
                        else f"not calibrated: {str(row.get('reason'))[:80]}"
                    )
                    print(
                        f"{name:24s} {seed:4d} {mode:>6s} {err} {row['cpu_s']:6.1f}  "
                        f"{row['moving']}",
                        flush=True,
                    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
