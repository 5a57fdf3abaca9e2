"""Recorded error vs. the recommended constant change, the seed's controller and ours.

Simulates the cases of docs/advice.md (the tunnel, delay drifts, conventions the simulator
does not start with), audits each with its rig and prints one Markdown row per case:
Eq. 5 (us) and Eq. 6 (us^2) averaged over the three cameras, per policy of `what_if`,
and the action recommended. Run: `.venv/bin/python benchmarks/bench_advice.py` (about a
minute; logs go to a temporary folder).
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from syncaudit.audit.run import audit_log
from syncaudit.simulate.rig_file import rig_from_truth
from syncaudit.simulate.sync_log import simulate_sync_log, sync_sim_config

CASES: list[tuple[str, dict[str, Any]]] = [
    ("tunnel (2 -> 12 -> 2 ms)", {}),
    ("steady light, correct delay", {"tunnel": False}),
    ("steady light, delay +300 us", {"tunnel": False, "delay_error_us": 300.0}),
    ("tunnel, delay -500 us", {"delay_error_us": -500.0}),
    ("tunnel, stamp exposure_end", {"stamp": "exposure_end"}),
    ("tunnel, stamp trigger (246)", {"stamp": "trigger"}),
    ("tunnel, trigger packet first_after", {"trigger_packet": "first_after"}),
    ("tunnel, Pandar40P", {"lidar": "Pandar40P"}),
]
POLICIES = (
    "as recorded",
    "constant shift",
    "seed controller (Eq. 2, running average)",
    "feed-forward + dead band (ours)",
)


def _case(folder: Path, name: str, settings: dict[str, Any]) -> str:
    out = folder / f"{abs(hash(name))}.mcap"
    truth = simulate_sync_log(out, sync_sim_config(duration_s=10.0, seed=5, **settings))
    result = audit_log(out, rig_from_truth(truth), jobs=1)
    cells = []
    for policy in POLICIES:
        rows = [w for c in result.cameras for w in c.advice.what_if if w.policy == policy]
        mean = np.mean([w.error_mean_ns for w in rows]) / 1e3
        var = np.mean([w.error_var_ns2 for w in rows]) / 1e6
        cells.append(f"{mean:.0f} / {var:.0f}")
    floor = np.mean([c.advice.floor.error_mean_ns for c in result.cameras]) / 1e3
    actions = sorted({c.advice.action for c in result.cameras})
    return f"| {name} | " + " | ".join(cells) + f" | {floor:.0f} | {', '.join(actions)} |"


def main() -> None:
    """Print the table."""
    print(
        "| case | recorded | constant shift | seed controller | ours | floor | advice |\n"
        "|---|---|---|---|---|---|---|"
    )
    with tempfile.TemporaryDirectory() as folder:
        for name, settings in CASES:
            print(_case(Path(folder), name, settings), flush=True)


if __name__ == "__main__":
    main()
