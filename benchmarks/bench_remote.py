"""Benchmark: audit a log over a loopback HTTP server (ranged reads) vs from local disk.

Prints the wall time of each (median of `--repeat` interleaved rounds, in this process,
imports warm), their ratio (target <= 1.3), and the bytes fetched against the file size
and against the bytes of the chunks that hold audited topics (target <= 1.05), with the
load average. The remote audit is `audit_log(URL)`: the parent fetches the MCAP's index,
each chunk worker streams its runs of chunks into memory (`logs/mcap_remote.py`).

The server runs in its own process on 127.0.0.1 and serves the file from the same page
cache the local audit reads, so the ratio is the cost of HTTP on this machine (whose two
cores the server shares with the audit), not of a network:
- `threaded` (default): the standard library's ThreadingHTTPServer with a Range handler
  that sends each range with one blocking `socket.sendfile` (sendfile(2): no copy through
  user space; the stock `copyfile` would copy 64 KB blocks through Python). Measured the
  cheaper of the two: ~0.4 CPU s to serve the 2.1 GB log, against ~0.9 for aiohttp;
- `aiohttp`: aiohttp's static file route, a real, well-kept server that honours Range
  and also uses sendfile, but non-blocking: the event loop wakes each time the socket
  has room and sends what fits.

The log: `--quick` (alias `--short`) the bundled sample (seconds; run by the tests);
by default the 2 GB log of `bench_audit.py` from its cache (`--cache-dir`, never written
to when the log is there); `--log PATH` any MCAP with `PATH.rig.yaml` beside it.
`--clients` instead measures the HTTP clients the reader could use on the same server.
`--transfer` adds the transfer alone (the log moved into one buffer by `preadv` and by
ranged GETs, client and server CPU split into user and system) and the floor ratio that
CPU puts under the audit on this machine's cores, with and without the server's share.

    flock /work/bench/machine.lock python benchmarks/bench_remote.py --cache-dir /work/bench/cache \
        --repeat 5 --transfer
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "sample_logs" / "pandar40p_adaptive.mcap"
RANGE = re.compile(r"bytes=(\d+)-(\d*)$")
CLIENT_RANGE_BYTES = 24 << 20
CLIENT_TOTAL_BYTES = 768 << 20


# -- servers (run in a child process: `--serve ROOT`) ------------------------------------


class _Handler(SimpleHTTPRequestHandler):
    """Static files with single-range support, sent with sendfile; keep-alive; quiet."""

    protocol_version = "HTTP/1.1"  # persistent connections, as object stores keep them
    disable_nagle_algorithm = True
    """TCP_NODELAY, as real servers set it on keep-alive connections (nginx's `tcp_nodelay
    on`, aiohttp's default): with Nagle, a reply's last partial segment waits for the
    client's delayed ACK, ~40 ms per range on Linux."""

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
            self.connection.sendfile(handle, start, end - start)


def _serve(root: Path, kind: str, parent_pid: int) -> None:
    """Serve `root` on an ephemeral loopback port; print the port; run until killed, or
    until the benchmark `parent_pid` dies (killed runs left orphan servers behind)."""
    from syncaudit.workers import die_with_parent

    die_with_parent(parent_pid)
    if kind == "threaded":
        handler = type("H", (_Handler,), {})
        handler.__init__ = lambda self, *a, **k: _Handler.__init__(  # type: ignore[method-assign]
            self, *a, directory=str(root), **k
        )
        server = ThreadingHTTPServer(("127.0.0.1", 0), handler)
        server.daemon_threads = True
        print(server.server_address[1], flush=True)
        server.serve_forever()
        return
    import asyncio

    from aiohttp import web

    async def main() -> None:
        app = web.Application()
        app.router.add_static("/", root, follow_symlinks=True)
        runner = web.AppRunner(app, access_log=None)
        await runner.setup()
        site = web.TCPSite(runner, "127.0.0.1", 0)
        await site.start()
        sockets = site._server.sockets if site._server else []  # type: ignore[union-attr]
        print(sockets[0].getsockname()[1], flush=True)
        await asyncio.Event().wait()

    asyncio.run(main())


class Server:
    """A server child process over a folder holding (a link to) the log."""

    def __init__(self, root: Path, kind: str) -> None:
        self.kind = kind
        self.process = subprocess.Popen(
            [
                sys.executable,
                __file__,
                "--serve",
                str(root),
                "--server",
                kind,
                "--parent-pid",
                str(os.getpid()),
            ],
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.process.stdout is not None
        port = self.process.stdout.readline().strip()
        if not port:
            raise SystemExit(f"the {kind} server did not start")
        self.base = f"http://127.0.0.1:{port}"

    def cpu_s(self) -> float:
        """CPU seconds (user + system) the server has used so far."""
        return sum(self.cpu_split_s())

    def cpu_split_s(self) -> tuple[float, float]:
        """(user, system) CPU seconds the server has used so far."""
        fields = Path(f"/proc/{self.process.pid}/stat").read_text().rsplit(")", 1)[1].split()
        tick = os.sysconf("SC_CLK_TCK")
        return int(fields[11]) / tick, int(fields[12]) / tick

    def stop(self) -> None:
        """End the child."""
        self.process.terminate()
        self.process.wait(10)


# -- the log ---------------------------------------------------------------------------


def bench_log(cache: Path) -> Path:
    """bench_audit.py's 2 GB log in `cache` (generated there only if missing)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_audit

    name = bench_audit._log_name(2.0, 1)
    log = cache / name
    if bench_audit.meta_path(log).exists() and log.exists():
        return log
    if not os.access(cache, os.W_OK):
        raise SystemExit(f"{log} is missing and {cache} is not writable")
    bench_audit.prepare_logs(cache, 2.0, Path(tempfile.gettempdir()), 3_600.0)
    return log


# -- the comparison --------------------------------------------------------------------


def _timed(run: Callable[[], Any]) -> tuple[float, float, Any]:
    """(wall s, CPU s of this process and its waited-for children, result)."""
    before, cpu = time.perf_counter(), _cpu_s()
    result = run()
    return time.perf_counter() - before, _cpu_s() - cpu, result


def _cpu_s() -> float:
    times = os.times()
    return times.user + times.system + times.children_user + times.children_system


def compare(log: Path, args: argparse.Namespace) -> dict[str, Any]:
    """Local and remote audits of `log`, interleaved; the figures."""
    from syncaudit.audit.run import audit_log
    from syncaudit.logs import open_log
    from syncaudit.rig import load_rig

    rig = load_rig(Path(f"{log}.rig.yaml"))
    with tempfile.TemporaryDirectory(prefix="bench-remote-") as tmp:
        root = Path(tmp)
        (root / log.name).symlink_to(log)
        server = Server(root, args.server)
        url = f"{server.base}/{log.name}"
        try:
            local_ref = audit_log(log, rig, jobs=args.jobs).to_dict()  # warm: imports, cache
            local: list[tuple[float, float]] = []
            remote: list[tuple[float, float, float]] = []
            stats: dict[str, Any] = {}
            for _ in range(args.repeat):
                wall, cpu, _ = _timed(lambda: audit_log(log, rig, jobs=args.jobs))
                local.append((wall, cpu))
                served = server.cpu_s()

                def audit_remote() -> tuple[Any, Any]:
                    # Open as the gate's job does: the audit's own open reuses its bytes,
                    # and the log counts every fetch (the workers' too).
                    with open_log(url) as opened:
                        return audit_log(url, rig, jobs=args.jobs), opened.fetch_stats

                wall, cpu, (result, fetch) = _timed(audit_remote)
                stats = fetch.to_dict()
                remote.append((wall, cpu, server.cpu_s() - served))
                got, want = result.to_dict(), dict(local_ref)
                got.pop("path", None), want.pop("path", None)
                if got != want:
                    raise SystemExit("remote and local audits differ")
        finally:
            server.stop()
    local_s = statistics.median(w for w, _ in local)
    remote_s = statistics.median(w for w, _, _ in remote)
    return {
        "log": str(log),
        "server": args.server,
        "jobs": args.jobs,
        "rounds": args.repeat,
        "size_bytes": stats["size_bytes"],
        "local_s": round(local_s, 3),
        "remote_s": round(remote_s, 3),
        "time_ratio": round(remote_s / local_s, 3),
        "local_cpu_s": round(statistics.median(c for _, c in local), 3),
        "remote_cpu_s": round(statistics.median(c for _, c, _ in remote), 3),
        "server_cpu_s": round(statistics.median(s for _, _, s in remote), 3),
        "local_runs_s": [round(w, 3) for w, _ in local],
        "remote_runs_s": [round(w, 3) for w, _, _ in remote],
        "fetched_bytes": stats["fetched_bytes"],
        "needed_chunk_bytes": stats["needed_chunk_bytes"],
        "fetched_over_needed": round(
            stats["fetched_bytes"] / max(1, stats["needed_chunk_bytes"]), 4
        ),
        "fetched_over_size": round(stats["fetched_bytes"] / max(1, stats["size_bytes"]), 4),
        "chunks_fetched": stats["chunks_fetched"],
        "chunks_total": stats["chunks_total"],
        "requests": stats["requests"],
        "loadavg": [round(x, 2) for x in os.getloadavg()],
    }


# -- the transfer alone ----------------------------------------------------------------


def _self_cpu_split_s() -> tuple[float, float]:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime, usage.ru_stime


def transfer_cost(log: Path, args: argparse.Namespace) -> dict[str, Any]:
    """CPU of moving the whole log into a 24 MiB buffer, no decoding: `preadv` from the
    page cache (what the local reader does) against ranged GETs from the loopback server
    into the same buffer (the remote reader's `RangeStream`), client and server, user and
    system; median of `--repeat` interleaved rounds. The difference is what HTTP on this
    machine adds to an audit, whatever the reader does above it."""
    from syncaudit.remote.ranges import HttpObject, RangeStream

    size = log.stat().st_size
    ranges = [(a, min(size, a + CLIENT_RANGE_BYTES)) for a in range(0, size, CLIENT_RANGE_BYTES)]
    buffer = memoryview(bytearray(CLIENT_RANGE_BYTES))
    rows: dict[str, list[tuple[float, float, float, float, float]]] = {"pread": [], "http": []}
    with tempfile.TemporaryDirectory(prefix="bench-remote-") as tmp:
        (Path(tmp) / log.name).symlink_to(log)
        server = Server(Path(tmp), args.server)
        obj = HttpObject(f"{server.base}/{log.name}")
        try:
            for _ in range(args.repeat):
                for kind in rows:
                    served, own, wall = server.cpu_split_s(), _self_cpu_split_s(), 0.0
                    wall = time.perf_counter()
                    if kind == "pread":
                        fd = os.open(log, os.O_RDONLY)
                        for start, end in ranges:
                            os.preadv(fd, [buffer[: end - start]], start)
                        os.close(fd)
                    else:
                        for start, end in ranges:
                            stream = RangeStream(obj, start, end, None)
                            stream.readinto(buffer[: end - start])
                            stream.close()
                    wall = time.perf_counter() - wall
                    after, served_after = _self_cpu_split_s(), server.cpu_split_s()
                    rows[kind].append(
                        (
                            wall,
                            after[0] - own[0],
                            after[1] - own[1],
                            served_after[0] - served[0],
                            served_after[1] - served[1],
                        )
                    )
        finally:
            server.stop()
    out: dict[str, Any] = {"bytes": size}
    for kind, values in rows.items():
        med = [statistics.median(v[i] for v in values) for i in range(5)]
        out[kind] = {
            "wall_s": round(med[0], 3),
            "client_user_s": round(med[1], 3),
            "client_sys_s": round(med[2], 3),
            "server_user_s": round(med[3], 3),
            "server_sys_s": round(med[4], 3),
        }
    pread, http = out["pread"], out["http"]
    out["http_extra_cpu_s"] = round(
        sum(http[k] for k in http if k != "wall_s") - sum(pread[k] for k in pread if k != "wall_s"),
        3,
    )
    return out


def floor_ratio(figures: dict[str, Any], cores: int) -> dict[str, float]:
    """The least remote/local wall ratio the CPU allows: the local audit's CPU plus what
    the transfer adds, on `cores` cores used at best fully (`all_cores`) or as well as the
    local audit uses them (`local_parallelism`); and the same without the server's CPU (a
    server on another machine, as an object store is)."""
    local_cpu, local_s = figures["local_cpu_s"], figures["local_s"]
    extra = figures["transfer"]["http_extra_cpu_s"]
    http = figures["transfer"]["http"]
    server = http["server_user_s"] + http["server_sys_s"]
    used = max(local_cpu, 0.01) / local_s  # (CPU times tick in 10 ms)
    return {
        "local_cores_used": round(used, 2),
        "floor_all_cores": round((local_cpu + extra) / cores / local_s, 3),
        "floor_local_parallelism": round((local_cpu + extra) / used / local_s, 3),
        "floor_server_elsewhere": round((local_cpu + extra - server) / used / local_s, 3),
    }


# -- HTTP clients ----------------------------------------------------------------------


def _ranges(size: int) -> list[tuple[int, int]]:
    total = min(size, CLIENT_TOTAL_BYTES)
    return [(a, min(total, a + CLIENT_RANGE_BYTES)) for a in range(0, total, CLIENT_RANGE_BYTES)]


def _client_http_client(url: str, ranges: list[tuple[int, int]]) -> int:
    """http.client, one connection, readinto a reused buffer (what the reader does)."""
    from syncaudit.remote.ranges import HttpObject, RangeStream

    obj, buffer, got = HttpObject(url), bytearray(CLIENT_RANGE_BYTES), 0
    for start, end in ranges:
        stream = RangeStream(obj, start, end, None)
        stream.readinto(memoryview(buffer)[: end - start])
        stream.close()
        got += end - start
    return got


def _client_urllib3(url: str, ranges: list[tuple[int, int]]) -> int:
    """urllib3 PoolManager, streamed readinto a reused buffer (it copies via read())."""
    import urllib3

    pool, buffer, got = urllib3.PoolManager(), bytearray(CLIENT_RANGE_BYTES), 0
    for start, end in ranges:
        reply = pool.request(
            "GET", url, headers={"Range": f"bytes={start}-{end - 1}"}, preload_content=False
        )
        view = memoryview(buffer)[: end - start]
        filled = 0
        while filled < len(view):
            n = reply.readinto(view[filled:])
            if not n:
                raise SystemExit("urllib3: short reply")
            filled += n
        reply.release_conn()
        got += filled
    return got


def _client_requests(url: str, ranges: list[tuple[int, int]]) -> int:
    """requests Session, each range as `.content` bytes."""
    import requests

    session, got = requests.Session(), 0
    for start, end in ranges:
        got += len(session.get(url, headers={"Range": f"bytes={start}-{end - 1}"}).content)
    return got


def _client_fsspec_cat_file(url: str, ranges: list[tuple[int, int]]) -> int:
    """fsspec's HTTPFileSystem (aiohttp under a sync wrapper), one `cat_file` per range."""
    import fsspec

    fs, got = fsspec.filesystem("http"), 0
    for start, end in ranges:
        got += len(fs.cat_file(url, start=start, end=end))
    return got


def _client_fsspec_cat_ranges(url: str, ranges: list[tuple[int, int]]) -> int:
    """fsspec's `cat_ranges`, 8 ranges at a time (concurrent on aiohttp)."""
    import fsspec

    fs, got = fsspec.filesystem("http"), 0
    for at in range(0, len(ranges), 8):
        part = ranges[at : at + 8]
        datas = fs.cat_ranges([url] * len(part), [a for a, _ in part], [b for _, b in part])
        got += sum(len(d) for d in datas)
    return got


CLIENTS: dict[str, Callable[[str, list[tuple[int, int]]], int]] = {
    "http.client": _client_http_client,
    "urllib3": _client_urllib3,
    "requests": _client_requests,
    "fsspec cat_file": _client_fsspec_cat_file,
    "fsspec cat_ranges": _client_fsspec_cat_ranges,
}


def compare_clients(log: Path, args: argparse.Namespace) -> dict[str, Any]:
    """Each client fetching the same ranges into memory, interleaved rounds; median."""
    ranges = _ranges(log.stat().st_size)
    total = sum(b - a for a, b in ranges)
    runs: dict[str, list[tuple[float, float]]] = {name: [] for name in CLIENTS}
    with tempfile.TemporaryDirectory(prefix="bench-remote-") as tmp:
        (Path(tmp) / log.name).symlink_to(log)
        server = Server(Path(tmp), args.server)
        url = f"{server.base}/{log.name}"
        try:
            for _ in range(args.repeat):
                for name, client in CLIENTS.items():
                    wall, cpu, got = _timed(lambda client=client: client(url, ranges))
                    assert got == total, name
                    runs[name].append((wall, cpu))
        finally:
            server.stop()
    figures: dict[str, Any] = {"bytes": total, "range_bytes": CLIENT_RANGE_BYTES}
    for name, values in runs.items():
        wall = statistics.median(w for w, _ in values)
        figures[name] = {
            "wall_s": round(wall, 3),
            "gb_per_s": round(total / wall / 1e9, 2),
            "client_cpu_s": round(statistics.median(c for _, c in values), 3),
        }
    figures["loadavg"] = [round(x, 2) for x in os.getloadavg()]
    return figures


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        return os.cpu_count() or 1


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--log", type=Path, help="MCAP log with LOG.rig.yaml beside it")
    parser.add_argument("--quick", "--short", action="store_true", help="the bundled sample")
    parser.add_argument(
        "--cache-dir", type=Path, help="bench_audit.py's cache (default: benchmarks/.cache)"
    )
    parser.add_argument("--server", choices=("threaded", "aiohttp"), default="threaded")
    parser.add_argument("--jobs", type=int, default=2, help="chunk workers of each audit")
    parser.add_argument("--repeat", type=int, default=3, help="interleaved rounds (median)")
    parser.add_argument("--clients", action="store_true", help="compare HTTP clients instead")
    parser.add_argument(
        "--transfer",
        action="store_true",
        help="also measure the transfer alone (pread vs HTTP, CPU split) and the floor ratio",
    )
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    parser.add_argument("--serve", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--parent-pid", type=int, default=0, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve is not None:
        _serve(args.serve, args.server, args.parent_pid or os.getppid())
        return 0
    if args.quick:
        log = SAMPLE
    elif args.log is not None:
        log = args.log.resolve()
    else:
        log = bench_log(args.cache_dir or REPO / "benchmarks" / ".cache")
    figures = compare_clients(log, args) if args.clients else compare(log, args)
    if args.transfer and not args.clients:
        figures["transfer"] = transfer_cost(log, args)
        figures.update(floor_ratio(figures, _cores()))
    if args.json:
        print(json.dumps(figures))
    else:
        for key, value in figures.items():
            print(f"{key:22} {value}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
