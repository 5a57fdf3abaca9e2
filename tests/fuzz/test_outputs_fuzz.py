"""The outputs class: every output flag against existing targets of every kind (see
`outputs_campaign`). CI runs each flag against one kind (rotating, so that every kind is
met); the whole matrix is `slow` (`benchmarks/fuzz_campaign.py --outputs` runs it too).
"""

from __future__ import annotations

from pathlib import Path

import pytest
from outputs_campaign import FLAGS, INPUT_KINDS, KINDS, Case, cases, real_data_present, run_case

needs_data = pytest.mark.skipif(not real_data_present(), reason="no /work/shared/data")


def _ci_cases() -> list[Case]:
    """Each flag against one kind, rotating over the kinds; --overwrite on every other."""
    chosen: list[Case] = []
    step = 0
    for flag in FLAGS:
        kind = KINDS[step % len(KINDS)]
        while kind in INPUT_KINDS and flag.input_path is None:
            step += 1
            kind = KINDS[step % len(KINDS)]
        step += 1
        chosen.append(Case(flag, kind, overwrite=step % 2 == 0))
    return chosen


def test_the_ci_cases_meet_every_kind_and_flag() -> None:
    chosen = _ci_cases()
    assert {c.kind for c in chosen} == set(KINDS)
    assert {c.flag.name for c in chosen} == {f.name for f in FLAGS}
    assert {c.overwrite for c in chosen} == {False, True}


@needs_data
@pytest.mark.parametrize("case", _ci_cases(), ids=lambda c: c.id)
def test_an_output_flag_never_changes_what_the_tool_did_not_write(
    case: Case, tmp_path: Path
) -> None:
    result = run_case(case, tmp_path / "work")
    assert result.code in result.expected, result.stderr
    assert result.unchanged, "the target's bytes changed"
    assert not result.leftovers
    if result.code in (8, 64):
        assert result.stderr.startswith("error: ") and result.stderr.count("\n") == 1
    if case.kind not in ("own",) and result.code == 8:
        assert "--overwrite" not in result.stderr  # never invites replacing what is not ours


@pytest.mark.slow
@needs_data
@pytest.mark.parametrize("case", list(cases()), ids=lambda c: c.id)
def test_the_whole_outputs_matrix(case: Case, tmp_path: Path) -> None:
    result = run_case(case, tmp_path / "work")
    assert result.ok, (
        result.code,
        result.expected,
        result.unchanged,
        result.leftovers,
        result.stderr,
    )
