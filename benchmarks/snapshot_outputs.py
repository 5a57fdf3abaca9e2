"""Write every command's JSON output on a fixed set of logs into one folder.

Run it before and after a change that must not change results, then compare the two
folders byte by byte (`diff -r before/ after/`). The logs: the bundled samples, the real
recordings in ../shared/data/lidar, a simulated log in every container (same seed), and a
simulated calibration session. Paths inside the outputs are made relative to the logs'
folder so two checkouts compare equal.

    python benchmarks/snapshot_outputs.py OUT_DIR [--quick]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data" / "lidar"
CONTAINERS = {"mcap": "sim.mcap", "mcap-ros1": "sim_ros1.mcap", "db3": "sim_db3", "bag": "sim.bag"}


def run(args: list[str], out: Path, cwd: Path) -> None:
    """Run one syncaudit command; keep its stdout and exit code (paths made relative)."""
    proc = subprocess.run(
        [sys.executable, "-m", "syncaudit", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        env={**os.environ, "COLUMNS": "200", "NO_COLOR": "1"},
        check=False,
    )
    text = proc.stdout.replace(str(cwd), "<logs>")
    if text.startswith("{"):  # wall-clock stage timings are the one field that moves run to run
        data = json.loads(text)
        data.pop("timings_s", None)
        text = json.dumps(data, indent=2)
    text += f"\n# exit {proc.returncode}\n"
    out.write_text(text)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--quick", action="store_true", help="skip the calibration session")
    args = parser.parse_args()
    out: Path = args.out.resolve()
    if out.exists():
        print(f"{out} exists: choose a new folder", file=sys.stderr)
        return 2
    logs = out / "logs"
    logs.mkdir(parents=True)
    for name in os.listdir(REPO / "sample_logs"):
        source = REPO / "sample_logs" / name
        if source.is_dir():
            shutil.copytree(source, logs / name)
        else:
            shutil.copy(source, logs / name)
    for fmt, name in CONTAINERS.items():
        run(
            ["simulate", "sync", name, "--duration", "6", "--seed", "3", "--format", fmt],
            out / f"simulate-{fmt}.txt",
            logs,
        )
    subjects = sorted(
        p.name for p in logs.iterdir() if not p.name.endswith((".json", ".yaml", ".sh"))
    )
    for name in subjects:
        rig = logs / f"{name}.rig.yaml"
        if not rig.exists():
            rig = logs / f"{name.removesuffix('.db3')}.rig.yaml"
        run(["info", name, "--json"], out / f"info-{name}.json", logs)
        run(["audit", name, "--json"], out / f"audit-guessed-{name}.json", logs)
        if rig.exists():
            run(["audit", name, "--rig", rig.name, "--json"], out / f"audit-rig-{name}.json", logs)
    if DATA.is_dir():
        for recording in sorted(p for p in DATA.iterdir() if p.is_dir()):
            for item in sorted(recording.iterdir()):
                if item.suffix == ".pcd":
                    continue
                target = logs / f"real_{recording.name}_{item.name}"
                (shutil.copytree if item.is_dir() else shutil.copy)(item, target)
                run(["info", target.name, "--json"], out / f"info-{target.name}.json", logs)
                run(["audit", target.name, "--json"], out / f"audit-{target.name}.json", logs)
    gate_inputs = [n for n in subjects if n.startswith("sim")]
    # --accept-bad: the simulated logs fail the default policy (issue 24: --init refuses them).
    run(
        ["gate", "--init", "--accept-bad", "-o", "policy.yaml", *gate_inputs],
        out / "gate-init.txt",
        logs,
    )
    shutil.copy(logs / "policy.yaml", out / "gate-policy.yaml")
    run(
        ["gate", "--policy", "policy.yaml", "--no-db", "--json-out", "gate.json", *subjects],
        out / "gate.txt",
        logs,
    )
    shutil.copy(logs / "gate.json", out / "gate.json")
    if not args.quick:
        run(["simulate", "calib", "calib.mcap", "--seed", "1"], out / "simulate-calib.txt", logs)
        # One registration thread: GICP's reductions on two threads differ in the last bits.
        (logs / "calib.yaml").write_text("registration:\n  num_threads: 1\n")
        run(["calib", "calib.mcap", "--config", "calib.yaml", "--json"], out / "calib.json", logs)
    shutil.rmtree(logs)
    print(f"wrote {len(list(out.iterdir()))} outputs to {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
