"""Fuzz suite options: `--fuzz-long` runs the long campaign (>= 2,000 mutants)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))


def pytest_addoption(parser: pytest.Parser) -> None:
    """`--fuzz-long` and `--fuzz-mutants N` (this directory only: `pytest tests/fuzz ...`)."""
    group = parser.getgroup("fuzz")
    group.addoption("--fuzz-long", action="store_true", help="run the long fuzz campaign")
    group.addoption("--fuzz-mutants", type=int, default=None, help="mutants to run")
