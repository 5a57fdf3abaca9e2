"""Audit time and memory against the number of cameras in the rig (issue 10 item 9).

    python benchmarks/bench_many_cameras.py 250 500 1000 2000

Each rig lists N cameras on the three camera topic sets of the VLP-16 sample log
(camera i uses set i % 3, at azimuth 360 * i / N). Each size runs `syncaudit audit`
in a subprocess; prints wall seconds and the run's peak RSS (wait4) per size.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
LOG = REPO / "sample_logs" / "vlp16_three_cameras.mcap"


def rig_with(cameras: int) -> dict[str, object]:
    """The sample's rig with `cameras` cameras spread over its three topic sets."""
    base = yaml.safe_load(Path(f"{LOG}.rig.yaml").read_text())
    sets = base["cameras"]
    base["cameras"] = [
        {
            "name": f"cam{i:05d}",
            "image_topic": sets[i % 3]["image_topic"],
            "exposure_topic": sets[i % 3]["exposure_topic"],
            "trigger_topic": sets[i % 3]["trigger_topic"],
            "azimuth_deg": round(360.0 * i / cameras, 6) % 360.0,
        }
        for i in range(cameras)
    ]
    return base


def run(cameras: int, work: Path) -> tuple[float, float, int]:
    """(wall s, peak RSS MB, exit code) of one audit."""
    rig = work / f"rig{cameras}.yaml"
    rig.write_text(yaml.safe_dump(rig_with(cameras)))
    cmd = [sys.executable, "-m", "syncaudit.cli", "audit", str(LOG), "--rig", str(rig), "--json"]
    start = time.monotonic()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    wall = time.monotonic() - start
    assert proc.stderr is not None
    err = proc.stderr.read().decode().strip()
    if err:
        print(f"  {cameras}: {err[:200]}", file=sys.stderr)
    return wall, usage.ru_maxrss / 1024, proc.returncode


def main() -> None:
    """Run each size given on the command line."""
    sizes = [int(a) for a in sys.argv[1:]] or [3, 250, 500, 1000]
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            wall, rss, code = run(n, Path(tmp))
            print(f"{n:6d} cameras: {wall:6.2f} s, {rss:6.0f} MB, exit {code}")


if __name__ == "__main__":
    main()
