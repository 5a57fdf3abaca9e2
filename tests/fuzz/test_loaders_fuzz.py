"""The loaders class of the fuzz campaign in CI: `CI_LOADER_MUTANTS` hostile config files,
every loader in turn, each given to the CLI command that reads it (see loader_campaign)."""

from __future__ import annotations

import tempfile
from pathlib import Path

from campaign import CI_SEED
from loader_campaign import LOADERS, loader_plan, run_loader_campaign

CI_LOADER_MUTANTS = 2 * len(LOADERS)


def test_hostile_config_files_are_refused_cleanly() -> None:
    mutants = loader_plan(CI_LOADER_MUTANTS, CI_SEED)
    with tempfile.TemporaryDirectory(prefix="syncaudit-loader-fuzz-") as root:
        outcomes = run_loader_campaign(mutants, Path(root))
    problems = {m: (o.description, o.problems) for m, o in outcomes.items() if o.problems}
    assert problems == {}
    assert {m.loader for m in mutants} == set(LOADERS)
