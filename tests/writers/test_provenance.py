"""The mark of the tool's outputs: every writer leaves it, real recordings never carry it,
and `--overwrite` (`OutputSet(overwrite=True)`) replaces only what carries it."""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import pytest

from syncaudit.errors import OutputError
from syncaudit.logs import open_log
from syncaudit.writers.log_writer import FORMATS, LogFormat, open_writer
from syncaudit.writers.outputs import OutputSet
from syncaudit.writers.provenance import refusal, sidecar_of

DATA = Path("/work/shared/data")
REAL = {
    "rosbag2 folder": DATA / "lidar" / "hesai_40p" / "1673400149412331409",
    "ROS 1 bag": DATA / "lidar" / "ouster_os1_512x10" / "512x10_raw.bag",
    "MCAP": DATA / "mcap-conformance" / "OneMetadata" / "OneMetadata.mcap",
    "PCD": DATA / "lidar" / "hesai_40p" / "1673400149711850138.pcd",
    "JSON": DATA / "mcap-conformance" / "OneMetadata" / "OneMetadata.json",
}
needs_data = pytest.mark.skipif(
    not all(p.exists() for p in REAL.values()), reason="no /work/shared/data"
)


def _hashes(path: Path) -> dict[str, str]:
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    return {
        str(f.relative_to(path.parent)): hashlib.sha256(f.read_bytes()).hexdigest() for f in files
    }


def _write_log(path: Path, fmt: LogFormat, **kwargs: object) -> None:
    with open_writer(path, fmt, **kwargs) as writer:  # type: ignore[arg-type]
        writer.add_topic("/a", "std_msgs/msg/String")
        writer.write_msg("/a", 1_000, writer.new_msg("std_msgs/msg/String", data="x"))


@pytest.mark.parametrize("fmt", FORMATS)
def test_every_log_writer_leaves_the_mark_and_the_log_still_reads(fmt: str, tmp_path: Path) -> None:
    path = tmp_path / {"mcap": "a.mcap", "mcap-ros1": "a.mcap", "db3": "a", "bag": "a.bag"}[fmt]
    _write_log(path, fmt)  # type: ignore[arg-type]
    assert refusal(path) is None
    with open_log(path) as log:
        assert [log.deserialize(m).data for m in log.messages()] == ["x"]
    _write_log(path, fmt, overwrite=True)  # its own output: replaced
    assert refusal(path) is None


@needs_data
@pytest.mark.parametrize("kind", list(REAL))
def test_real_recordings_carry_no_mark_and_are_never_replaced(kind: str, tmp_path: Path) -> None:
    source = REAL[kind]
    target = tmp_path / source.name
    if source.is_dir():
        shutil.copytree(source, target)
    else:
        shutil.copyfile(source, target)
    before = _hashes(target)
    why = refusal(target)
    assert why is not None and "did not write" in why
    with pytest.raises(OutputError, match="not replacing it") as caught:
        OutputSet(overwrite=True).add(target, kind="dir" if target.is_dir() else "file")
    assert "--overwrite" not in str(caught.value)
    formats = {".mcap": ("mcap", "mcap-ros1"), ".bag": ("bag",), "": ("db3",)}
    for fmt in formats.get(target.suffix, ()):
        with pytest.raises(OutputError, match="not replacing it"):
            _write_log(target, fmt, overwrite=True)  # type: ignore[arg-type]
    assert _hashes(target) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [target.name]


def test_a_bag_folder_with_the_mark_and_other_files_is_refused(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    _write_log(bag, "db3")
    (bag / "notes.txt").write_text("mine")
    why = refusal(bag)
    assert why is not None and "other than a bag's" in why


def test_a_csv_is_the_tools_while_its_sidecar_matches(tmp_path: Path) -> None:
    csv = tmp_path / "f.csv"
    with OutputSet() as outputs:
        outputs.write_text(csv, "a,b\n1,2\n")
    assert sidecar_of(csv).is_file() and refusal(csv) is None
    csv.write_text("a,b\n1,3\n")  # edited by the user since
    why = refusal(csv)
    assert why is not None and "has changed" in why
    sidecar_of(csv).unlink()
    assert "no .f.csv.syncaudit" in str(refusal(csv))


def test_a_symbolic_link_is_never_replaced_even_to_the_tools_output(tmp_path: Path) -> None:
    own = tmp_path / "own.mcap"
    _write_log(own, "mcap")
    link = tmp_path / "link.mcap"
    link.symlink_to(own)
    with pytest.raises(OutputError, match="symbolic link"):
        OutputSet(overwrite=True).add(link)
    assert link.is_symlink()


def test_a_document_that_only_mentions_the_mark_is_not_the_tools(tmp_path: Path) -> None:
    doc = tmp_path / "outputs.md"
    shutil.copyfile(Path(__file__).resolve().parents[2] / "docs" / "outputs.md", doc)
    assert "written by syncaudit" in doc.read_text()
    assert refusal(doc) is not None
    page = tmp_path / "page.html"
    page.write_text('<!doctype html><body><p>&lt;meta name="generator" content="written by '
                    'syncaudit 0.1.0"&gt;</p>\n')  # fmt: skip
    assert refusal(page) is not None
