"""Test helper: files that stand for earlier outputs of syncaudit (they carry its mark)."""

from __future__ import annotations

from pathlib import Path

from syncaudit.writers.provenance import (
    COMMENT_MARK,
    HTML_MARK,
    MARKUP_MARK,
    WRITTEN_BY,
    sidecar_of,
    sidecar_text,
)


def write_ours(path: Path, text: str = "previous") -> str:
    """Write `path` as syncaudit would have (mark by suffix); return what was written."""
    suffix = path.suffix.lower()
    if suffix == ".json" or suffix == "":
        content = f'{{"written_by": "{WRITTEN_BY}", "text": "{text}"}}\n'
    elif suffix == ".html":
        content = f"<!doctype html><html><head>{HTML_MARK}</head><p>{text}</p>\n"
    elif suffix in (".yaml", ".yml", ".toml"):
        content = f"{COMMENT_MARK}# {text}\n"
    elif suffix in (".md", ".xml"):
        content = f"{MARKUP_MARK}{text}\n"
    elif suffix == ".csv":
        content = f"{text}\n"
        sidecar_of(path).write_text(sidecar_text(content.encode()))
    else:
        raise ValueError(f"no mark for {path}")
    path.write_text(content)
    return content
