"""Benchmark: audit a log over a loopback HTTP server (ranged reads) vs from local disk.

Prints the wall time of each, their ratio (target <= 1.3), the bytes fetched against the
file size and against the bytes of the chunks that hold audited topics (target <= 1.05).
The server is a threaded `http.server` honouring single `Range: bytes=a-b` requests,
started here on 127.0.0.1; the file is served from the same disk (and page cache) the
local audit reads, so the ratio is the cost of HTTP and of the sparse copy, not of a
network. `--short` audits the bundled sample log (a few seconds: run by the tests);
`--log PATH` any MCAP with `PATH.rig.yaml` beside it (e.g. a bench_audit.py log).

    python benchmarks/bench_remote.py --short
    python benchmarks/bench_remote.py --log benchmarks/.cache/bench_2gb_x1_<key>.mcap
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import tempfile
import threading
import time
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "sample_logs" / "pandar40p_adaptive.mcap"
RANGE = re.compile(r"bytes=(\d+)-(\d*)$")


class _Handler(SimpleHTTPRequestHandler):
    """Static files with single-range support; quiet."""

    def log_message(self, format: str, *args: Any) -> None:
        """Quiet."""

    def do_GET(self) -> None:
        path = Path(self.translate_path(self.path))
        if not path.is_file():
            super().do_GET()
            return
        size = path.stat().st_size
        match = RANGE.match(self.headers.get("Range", "") or "")
        start, end = 0, size
        if match:
            start = int(match.group(1))
            end = min(size, int(match.group(2)) + 1) if match.group(2) else size
            self.send_response(206)
            self.send_header("Content-Range", f"bytes {start}-{end - 1}/{size}")
        else:
            self.send_response(200)
        self.send_header("Content-Length", str(end - start))
        self.send_header("Accept-Ranges", "bytes")
        self.end_headers()
        self.wfile.flush()
        with path.open("rb") as handle:
            # Zero-copy from the page cache, as a real object store's server would stream.
            self.connection.sendfile(handle, start, end - start)


def _serve(root: Path) -> tuple[ThreadingHTTPServer, str]:
    handler = type("H", (_Handler,), {})
    handler.__init__ = lambda self, *a, **k: _Handler.__init__(  # type: ignore[method-assign]
        self, *a, directory=str(root), **k
    )
    server = ThreadingHTTPServer(("127.0.0.1", 0), handler)
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, f"http://127.0.0.1:{server.server_address[1]}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--log", type=Path, help="MCAP log with LOG.rig.yaml beside it")
    parser.add_argument("--short", action="store_true", help="the bundled sample log")
    parser.add_argument("--jobs", type=int, default=2, help="chunk workers of each audit")
    parser.add_argument("--repeat", type=int, default=1, help="runs of each; the best is kept")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    parser.add_argument(
        "--scratch", type=Path, help="folder of the sparse copy (default: the temp folder)"
    )
    args = parser.parse_args(argv)
    log = SAMPLE if args.short or args.log is None else args.log.resolve()
    rig_file = Path(f"{log}.rig.yaml")

    from syncaudit.audit import audit_log
    from syncaudit.remote.fetch import fetch_log
    from syncaudit.remote.job import rig_topics
    from syncaudit.rig import load_rig

    rig = load_rig(rig_file)
    topics = rig_topics(str(rig_file))
    local_s: list[float] = []
    remote_s: list[float] = []
    fetch_s: list[float] = []
    stats: Any = None
    with tempfile.TemporaryDirectory(prefix="bench-remote-") as tmp:
        root = Path(tmp) / "www"
        root.mkdir()
        (root / log.name).symlink_to(log)
        server, base = _serve(root)
        try:
            audit_log(log, rig, jobs=args.jobs)  # warm-up: imports and page cache for both
            for _ in range(args.repeat):
                started = time.perf_counter()
                local = audit_log(log, rig, jobs=args.jobs).to_dict()
                local_s.append(time.perf_counter() - started)
                with tempfile.TemporaryDirectory(dir=args.scratch or tmp) as scratch:
                    started = time.perf_counter()
                    copy, stats = fetch_log(f"{base}/{log.name}", Path(scratch), topics=topics)
                    fetch_s.append(time.perf_counter() - started)
                    remote = audit_log(copy, rig, jobs=args.jobs).to_dict()
                    remote_s.append(time.perf_counter() - started)
                if remote["cameras"] != local["cameras"]:
                    print("remote and local audits differ", file=sys.stderr)
                    return 1
        finally:
            server.shutdown()
    figures = {
        "log": str(log),
        "scratch": str(args.scratch or tempfile.gettempdir()),
        "size_bytes": stats.size_bytes,
        "local_s": round(min(local_s), 3),
        "remote_s": round(min(remote_s), 3),
        "fetch_s": round(min(fetch_s), 3),
        "time_ratio": round(min(remote_s) / min(local_s), 3),
        "fetched_bytes": stats.fetched_bytes,
        "needed_chunk_bytes": stats.needed_chunk_bytes,
        "fetched_over_needed": round(stats.fetched_bytes / max(1, stats.needed_chunk_bytes), 4),
        "fetched_over_size": round(stats.fetched_bytes / max(1, stats.size_bytes), 4),
        "chunks_fetched": stats.chunks_fetched,
        "chunks_total": stats.chunks_total,
        "requests": stats.requests,
    }
    if args.json:
        print(json.dumps(figures))
    else:
        for key, value in figures.items():
            print(f"{key:22} {value}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
