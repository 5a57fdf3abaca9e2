"""The HTML report: well-formed, self-contained, and showing the audited numbers."""

from __future__ import annotations

from html.parser import HTMLParser
from pathlib import Path

from typer.testing import CliRunner

from syncaudit.cli import app

SAMPLE = Path(__file__).resolve().parents[2] / "sample_logs" / "vlp16_short.bag"


class _Collect(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.tags: list[str] = []
        self.text: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append(tag)
        for name, value in attrs:
            assert not (name in ("src", "href") and value and "://" in value), value

    def handle_data(self, data: str) -> None:
        self.text.append(data)


def test_html_report_of_sample_log(tmp_path: Path) -> None:
    out = tmp_path / "report.html"
    result = CliRunner().invoke(
        app,
        ["audit", str(SAMPLE), "--rig", f"{SAMPLE}.rig.yaml", "--html", str(out), "--json"],
    )
    assert result.exit_code == 0, result.output
    page = out.read_text()
    parser = _Collect()
    parser.feed(page)
    assert "script" not in parser.tags  # self-contained, static
    assert parser.tags.count("svg") == 3  # one error plot per camera
    text = " ".join(parser.text)
    for camera in ("front", "rear_left", "rear_right"):
        assert f"camera {camera}" in text
    assert "t_sleep recommended, Eq. 2" in text
    assert "FAIL" in text  # the sample's delay is 800 us early
    assert oct(out.stat().st_mode & 0o777) != oct(0o600)
