"""A full disk while writing outputs: exit 8 naming the output, nothing partial left.

Uses a 300 KiB tmpfs (needs root and mount rights; skipped otherwise).
"""

from __future__ import annotations

import gc
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from typer.testing import CliRunner

from syncaudit.cli import app

SAMPLE = Path(__file__).resolve().parents[2] / "sample_logs" / "vlp16_three_cameras.mcap"


@pytest.fixture
def nearly_full(tmp_path: Path) -> Iterator[Path]:
    """A tmpfs with about 24 KiB free."""
    mount = tmp_path / "disk"
    mount.mkdir()
    made = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=300k", "tmpfs", str(mount)],
        capture_output=True,
        check=False,
    )
    if made.returncode != 0:
        pytest.skip("cannot mount a tmpfs here (needs root)")
    try:
        (mount / "filler").write_bytes(bytes(280_000))
        yield mount
    finally:
        if subprocess.run(["umount", str(mount)], check=False).returncode != 0:
            subprocess.run(["umount", "-l", str(mount)], check=False)  # never leave it mounted


@pytest.mark.parametrize("name", ["p.db3", "p.mcap", "p.bag"])
def test_full_disk_is_an_output_error_naming_it(nearly_full: Path, name: str) -> None:
    result = CliRunner().invoke(
        app,
        [
            "audit",
            str(SAMPLE),
            "--rig",
            f"{SAMPLE}.rig.yaml",
            "--pairings",
            str(nearly_full / name),
            "--json-out",
            str(nearly_full / "a.json"),
        ],
    )
    assert result.exit_code == 8, result.output
    assert result.stderr.startswith(f"error: {nearly_full / Path(name).stem}")
    assert "full" in result.stderr or "No space" in result.stderr
    assert sorted(p.name for p in nearly_full.iterdir()) == ["filler"]
    del result  # its traceback may hold the failed sqlite connection until collected
    gc.collect()
    busy = subprocess.run(["umount", str(nearly_full)], capture_output=True, check=False)
    assert busy.returncode == 0, f"a file on the full disk is still open: {busy.stderr!r}"
    subprocess.run(["mount", "-t", "tmpfs", "tmpfs", str(nearly_full)], check=False)
