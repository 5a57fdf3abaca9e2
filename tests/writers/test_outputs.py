"""OutputSet: every target checked first, written aside, committed together or not at all."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from syncaudit.errors import OutputError, UsageError
from syncaudit.writers.outputs import OutputSet
from syncaudit.writers.provenance import BAG2_KEY, WRITTEN_BY


def _ours(text: str) -> str:
    """A JSON document this tool wrote (it carries the mark) holding `text`."""
    return f'{{"written_by": "{WRITTEN_BY}", "text": "{text}"}}'


def _names(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def test_commit_publishes_every_output_and_leaves_no_temporary(tmp_path: Path) -> None:
    with OutputSet() as outputs:
        outputs.add(tmp_path / "a.json")
        outputs.add(tmp_path / "b.csv")
        outputs.write_text(tmp_path / "a.json", "{}\n")
        outputs.write_text(tmp_path / "b.csv", "x\n")
        assert _names(tmp_path)[0].startswith(".syncaudit-")  # written aside until the end
        assert not (tmp_path / "a.json").exists()
    assert _names(tmp_path) == [".b.csv.syncaudit", "a.json", "b.csv"]  # a CSV's mark beside it


def test_failure_before_commit_keeps_previous_files(tmp_path: Path) -> None:
    (tmp_path / "a.json").write_text(_ours("old"))
    with pytest.raises(RuntimeError), OutputSet(overwrite=True) as outputs:
        outputs.write_text(tmp_path / "a.json", "new")
        raise RuntimeError("boom")
    assert (tmp_path / "a.json").read_text() == _ours("old")
    assert _names(tmp_path) == ["a.json"]


def test_interrupt_before_commit_keeps_previous_files(tmp_path: Path) -> None:
    (tmp_path / "a.json").write_text(_ours("old"))
    with pytest.raises(KeyboardInterrupt), OutputSet(overwrite=True) as outputs:
        outputs.write_text(tmp_path / "a.json", "new")
        raise KeyboardInterrupt
    assert _names(tmp_path) == ["a.json"] and (tmp_path / "a.json").read_text() == _ours("old")


def test_a_failed_rename_restores_what_was_replaced(tmp_path: Path) -> None:
    (tmp_path / "a.json").write_text(_ours("old a"))
    (tmp_path / "b.json").write_text(_ours("old b"))
    outputs = OutputSet(overwrite=True)
    outputs.write_text(tmp_path / "a.json", "new a")
    outputs.write_text(tmp_path / "b.json", "new b")
    # b's rename fails after a's succeeded: a gets its old content back.
    real_rename = os.rename
    failed: list[str] = []

    def flaky(src: object, dst: object) -> None:
        if str(dst).endswith("b.json") and ".syncaudit-" in str(src) and not failed:
            failed.append(str(dst))  # the first rename of b's new content onto b fails
            raise OSError(28, "No space left on device")
        real_rename(src, dst)  # type: ignore[arg-type]

    monkey = pytest.MonkeyPatch()
    monkey.setattr(os, "rename", flaky)
    try:
        with pytest.raises(OutputError, match=r"b.json: cannot write .*no output was changed"):
            outputs.commit()
    finally:
        monkey.undo()
    assert (tmp_path / "a.json").read_text() == _ours("old a")
    assert (tmp_path / "b.json").read_text() == _ours("old b")
    assert _names(tmp_path) == ["a.json", "b.json"]


def test_targets_are_checked_when_added(tmp_path: Path) -> None:
    (tmp_path / "there.json").write_text(_ours("x"))
    with pytest.raises(OutputError, match="exists \\(pass --overwrite"):
        OutputSet().add(tmp_path / "there.json")
    with pytest.raises(OutputError, match="does not exist"):
        OutputSet().add(tmp_path / "no" / "x.json")
    outputs = OutputSet(inputs=[tmp_path / "there.json"], overwrite=True)
    with pytest.raises(UsageError, match="input"):
        outputs.add(tmp_path / "there.json")
    outputs.add(tmp_path / "x.json")
    (tmp_path / "link").symlink_to(tmp_path)
    with pytest.raises(UsageError, match="given as two different outputs"):
        outputs.add(tmp_path / "link" / "x.json")
    outputs.discard()
    assert _names(tmp_path) == ["link", "there.json"]


def test_only_the_tools_own_bag_folder_is_replaced(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    bag.mkdir()
    info = f"rosbag2_bagfile_information:\n  custom_data:\n    {BAG2_KEY}: {WRITTEN_BY}\n"
    (bag / "metadata.yaml").write_text(info)
    (bag / "bag.db3").write_text("x")
    with OutputSet(overwrite=True) as outputs:
        (outputs.add(bag, kind="dir")).mkdir()
        (outputs.temporary(bag) / "new").write_text("new")
    assert _names(bag) == ["new"]
    other = tmp_path / "mine"
    other.mkdir()
    (other / "metadata.yaml").write_text("x")
    (other / "notes.txt").write_text("keep")
    with pytest.raises(OutputError, match="not replacing it"):
        OutputSet(overwrite=True).add(other, kind="dir")
    assert _names(other) == ["metadata.yaml", "notes.txt"]


def test_a_target_never_written_fails_the_commit(tmp_path: Path) -> None:
    outputs = OutputSet()
    outputs.add(tmp_path / "a.json")
    outputs.write_text(tmp_path / "b.json", "b")
    with pytest.raises(OutputError, match=r"a\.json: was not written"):
        outputs.commit()
    assert _names(tmp_path) == []
