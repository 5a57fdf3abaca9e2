"""Every file a gate run writes, planned before any work and committed together at the end.

The run's outputs go through one `OutputSet` (`syncaudit.writers.outputs`): `--junit`,
`--summary`, `--json-out` and the `--html DIR` reports are checked when the run starts
(an existing target without `--overwrite` is exit 8 naming `--overwrite`), written to
temporaries beside their targets as the run goes (per-log reports as their logs are
judged: memory stays flat), and renamed into place together at the end. A failed or
interrupted run leaves no temporary and every previous file as it was.

`--html DIR` is a folder of `index.html` and `logs/<log>-<key>.html`:

- DIR absent: the whole folder is one output (built as a temporary folder, renamed);
- DIR empty, or a gate report folder (it holds `index.html`) with `--overwrite`: the run
  adds its reports to it; `index.html` and each new report are file outputs, and
  `logs/` is one folder output when it does not exist yet. Reports of earlier runs stay:
  logs taken unchanged from the database link to them;
- any other existing folder is refused (never written into, never deleted).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from pathlib import Path

from syncaudit.errors import OutputError
from syncaudit.fleet.junit import render_junit
from syncaudit.fleet.log_pages import render_index
from syncaudit.fleet.record import JudgedLog
from syncaudit.fleet.run_summary import render_json, render_markdown
from syncaudit.writers.outputs import OutputSet
from syncaudit.writers.provenance import MARKUP_MARK, refusal

OVERWRITE_HINT = "use --overwrite to replace it"
_HIDDEN_TMP = ".syncaudit-"


def _visible_entries(folder: Path) -> list[Path]:
    """What a folder holds, without the hidden temporaries of a run still writing there."""
    return [p for p in folder.iterdir() if not p.name.startswith(_HIDDEN_TMP)]


def _marked_xml(text: str) -> str:
    """An XML document with the mark as a comment after its declaration."""
    if text.startswith("<?xml"):
        end = text.index("?>") + 2
        return text[:end] + "\n" + MARKUP_MARK.rstrip("\n") + text[end:]
    return MARKUP_MARK + text


class GateOutputs:
    """The outputs of one gate run (see the module doc); use as a context manager."""

    def __init__(
        self,
        *,
        junit: Path | None = None,
        summary: Path | None = None,
        json_out: Path | None = None,
        html_dir: Path | None = None,
        overwrite: bool = False,
        inputs: Iterable[str | Path | None] = (),
    ) -> None:
        self.outputs = OutputSet(overwrite=overwrite, inputs=inputs, overwrite_hint=OVERWRITE_HINT)
        self.junit, self.summary, self.json_out, self.html_dir = junit, summary, json_out, html_dir
        self._logs_tmp: Path | None = None
        """Temporary folder standing in for DIR/logs (None: reports are file outputs)."""
        self._index: Path | None = None
        self._index_is_output = False
        """DIR existed: index.html is a file output of its own (else inside DIR's temporary)."""
        self._written: set[str] = set()
        """Final paths (resolved) of the reports written by this run."""
        try:
            for option, target in (
                ("--junit", junit),
                ("--summary", summary),
                ("--json-out", json_out),
            ):
                if target is None:
                    continue
                if target.is_dir():
                    raise OutputError(f"{target}: is a directory ({option} needs a file)")
                self.outputs.claim(target)
            if html_dir is not None:
                self._plan_html(html_dir, overwrite)
        except BaseException:
            self.outputs.discard()
            raise

    def _plan_html(self, html: Path, overwrite: bool) -> None:
        self.outputs.refuse_input(html)
        if html.exists() and not html.is_dir():
            raise OutputError(f"{html}: exists and is not a directory (--html needs one)")
        if not html.exists():
            root = self.outputs.claim(html, kind="dir")
            self._make_dir(root / "logs", html)
            self._logs_tmp = root / "logs"
            self._index = root / "index.html"
            return
        entries = _visible_entries(html)
        index = html / "index.html"
        if entries:
            why = refusal(index) if index.is_file() else "holds no index.html"
            if why is not None:
                detail = f"its index.html {why}" if index.is_file() else why
                raise OutputError(
                    f"{html}: is an existing folder that is not a gate report folder ({detail}); "
                    "not writing into it (choose another --html folder)"
                )
        if entries and not overwrite:
            raise OutputError(
                f"{html}: exists and is not empty (use --overwrite to add this run's reports to it)"
            )
        logs = html / "logs"
        if logs.exists() and not logs.is_dir():
            raise OutputError(
                f"{logs}: exists and is not a directory (the --html reports go there)"
            )
        if not logs.exists():
            self._logs_tmp = self.outputs.add(logs, kind="dir")
            self._make_dir(self._logs_tmp, logs)
        self._index = html / "index.html"
        self._index_is_output = True
        self.outputs.claim(self._index)

    @staticmethod
    def _make_dir(tmp: Path, target: Path) -> None:
        try:
            tmp.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise OutputError(f"{target}: cannot write ({exc.strerror or exc})") from None

    def report_path(self, name: str) -> Path:
        """Where a report named `name` lands (DIR/logs/name), once committed."""
        if self.html_dir is None:
            raise RuntimeError("no --html folder in this run")
        return self.html_dir / "logs" / name

    def plan_report(self, name: str) -> None:
        """Check a report's target now (before the audits): DIR/logs/name exists -> --overwrite."""
        if self._logs_tmp is None:
            self.outputs.add(self.report_path(name))

    def write_report(self, log: JudgedLog, name: str, text: str) -> None:
        """Write one log's report into its temporary; its row records the final path."""
        final = self.report_path(name)
        if self._logs_tmp is not None:
            tmp = self._logs_tmp / name
            try:
                tmp.write_text(text, encoding="utf-8")
            except OSError as exc:
                raise OutputError(f"{final}: cannot write ({exc.strerror or exc})") from None
        else:
            self.outputs.write_text(final, text)
        log.report = str(final.resolve())
        self._written.add(log.report)

    def write_summaries(
        self, logs: list[JudgedLog], policy_fp: str, warnings: Sequence[str] = ()
    ) -> None:
        """JUnit, Markdown, JSON and the HTML index, into their temporaries."""
        if self.junit is not None:
            self.outputs.write_text(self.junit, _marked_xml(render_junit(logs)))
        if self.summary is not None:
            self.outputs.write_text(self.summary, MARKUP_MARK + render_markdown(logs, warnings))
        if self.json_out is not None:
            self.outputs.write_text(self.json_out, render_json(logs, policy_fp, warnings))
        if self.html_dir is not None and self._index is not None:
            links = {}
            for log in logs:
                if log.report and (log.report in self._written or Path(log.report).is_file()):
                    links[log.key] = os.path.relpath(log.report, self.html_dir.resolve())
            text = render_index(logs, links)
            if self._index_is_output:
                self.outputs.write_text(self._index, text)
            else:
                try:
                    self._index.write_text(text, encoding="utf-8")
                except OSError as exc:
                    raise OutputError(
                        f"{self.html_dir / 'index.html'}: cannot write ({exc.strerror or exc})"
                    ) from None

    def commit(self) -> None:
        """Move every output into place, all or none."""
        self.outputs.commit()

    def discard(self) -> None:
        """Remove every temporary; the previous files stay as they were."""
        self.outputs.discard()

    def __enter__(self) -> GateOutputs:
        return self

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.discard()
