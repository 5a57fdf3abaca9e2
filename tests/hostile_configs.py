"""Hostile config files, shared by the loader tests and the fuzz campaign's loaders class.

Each maker returns a file's bytes for one config format: an alias bomb (nine levels of nine
aliases: 9**9 values once expanded), deep nesting, a huge scalar, a key given twice, a
mapping of too many keys, a list of 400,000 values, bytes that are not UTF-8, and a file past the size cap.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

HOSTILE_KINDS = (
    "alias_bomb",
    "recursive_alias",
    "deep_nesting",
    "huge_scalar",
    "duplicate_key",
    "many_keys",
    "wide",
    "not_utf8",
    "oversized",
)
"""Every kind of hostile file, in the order the tests parametrize them."""


def alias_bomb(levels: int = 9, width: int = 9) -> bytes:
    """`a: &a [lol x9]`, `b: &b [*a x9]`, ... `i: [*h x9]`: width**levels values."""
    names = [chr(ord("a") + n) for n in range(levels)]
    lines = [f"{names[0]}: &{names[0]} [" + ", ".join(["lol"] * width) + "]"]
    for prev, name in itertools.pairwise(names):
        anchor = f"&{name} " if name != names[-1] else ""
        lines.append(f"{name}: {anchor}[" + ", ".join([f"*{prev}"] * width) + "]")
    return ("\n".join(lines) + "\n").encode()


def yaml_file(kind: str) -> bytes:
    """A hostile YAML config of `kind` (one of HOSTILE_KINDS)."""
    makers: dict[str, Callable[[], bytes]] = {
        "alias_bomb": alias_bomb,
        "recursive_alias": lambda: b"a: &a [1, *a]\n",
        "deep_nesting": lambda: b"a: " + b"[" * 5000 + b"]" * 5000 + b"\n",
        "huge_scalar": lambda: b"a: " + b"x" * 200_000 + b"\n",
        "duplicate_key": lambda: b"a: 1\nb: 2\na: 3\n",
        "many_keys": lambda: "".join(f"k{n}: {n}\n" for n in range(20_000)).encode(),
        "wide": lambda: b"a: [" + b",".join([b"1"] * 400_000) + b"]\n",
        "not_utf8": lambda: b"a: caf\xe9\n",
        "oversized": lambda: b"# padding\n" * 120_000,
    }
    return makers[kind]()


def json_text(kind: str) -> bytes:
    """A hostile JSON document of `kind` on one line (JSON has no aliases: those become
    the widest document that fits, 200,000 tiny values)."""
    makers: dict[str, Callable[[], bytes]] = {
        "alias_bomb": lambda: b'{"path": "a", "x": [' + b",".join([b"0"] * 250_000) + b"]}",
        "recursive_alias": lambda: b'{"path": "a", "x": ' + b"[" * 200 + b"]" * 200 + b"}",
        "deep_nesting": lambda: b'{"path": "a", "x": ' + b"[" * 50_000 + b"]" * 50_000 + b"}",
        "huge_scalar": lambda: b'{"path": "' + b"x" * 200_000 + b'"}',
        "duplicate_key": lambda: b'{"path": "a", "path": "b"}',
        "many_keys": lambda: (
            "{" + ",".join(f'"k{n}": {n}' for n in range(20_000)) + ', "path": "a"}'
        ).encode(),
        "wide": lambda: b'{"path": "a", "x": [' + b",".join([b"0"] * 400_000) + b"]}",
        "not_utf8": lambda: b'{"path": "caf\xe9"}',
        "oversized": lambda: b'{"path": "a"}\n' * 1_300_000,
    }
    return makers[kind]()


def csv_text(kind: str) -> bytes:
    """A hostile CSV manifest of `kind` (kinds CSV cannot express fall back to a wide row)."""
    makers: dict[str, Callable[[], bytes]] = {
        "huge_scalar": lambda: b"path,vehicle\n" + b"a," + b"x" * 200_000 + b"\n",
        "duplicate_key": lambda: b"path,vehicle,vehicle\na,v1,v2\n",
        "many_keys": lambda: b"path," + b",".join(b"c%d" % n for n in range(20_000)) + b"\n",
        "not_utf8": lambda: b"path,vehicle\na,caf\xe9\n",
        "oversized": lambda: b"path\n" + b"a.mcap\n" * 2_500_000,
    }
    maker = makers.get(kind, lambda: b"path,vehicle\n" + b'"a' + b"x" * 200_000 + b"\n")
    return maker()
