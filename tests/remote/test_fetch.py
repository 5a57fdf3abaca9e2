"""Remote MCAP reads over a real loopback HTTP server: ranged, sparse, retried, audited."""

from __future__ import annotations

from pathlib import Path

import pytest

from syncaudit.audit import audit_log
from syncaudit.errors import LogReadError
from syncaudit.remote.fetch import coalesce, fetch_log, public_url

from .conftest import ServerState

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / "sample_logs" / "vlp16_three_cameras.mcap"

pytest.importorskip("aiohttp")


def _serve(root: Path, name: str, source: Path) -> None:
    (root / name).symlink_to(source)


def test_public_url_drops_credentials_and_query() -> None:
    url = "https://user:secret@example.org:8443/logs/a.mcap?X-Amz-Signature=abc#frag"
    assert public_url(url) == "https://example.org:8443/logs/a.mcap"
    assert public_url("s3://bucket/key.mcap") == "s3://bucket/key.mcap"


def test_coalesce_merges_close_ranges_and_cuts_big_ones() -> None:
    assert coalesce([(0, 10), (12, 20), (1000, 1010)], gap=5, piece=100) == [
        (0, 20),
        (1000, 1010),
    ]
    assert coalesce([(0, 250)], gap=0, piece=100) == [(0, 100), (100, 200), (200, 250)]


def test_remote_mcap_audits_like_the_local_file(
    http_root: tuple[str, ServerState], tmp_path: Path
) -> None:
    base, state = http_root
    _serve(state.root, "log.mcap", SAMPLE)
    local, stats = fetch_log(f"{base}/log.mcap?token=xyz", tmp_path)
    assert stats.url == f"{base}/log.mcap"  # no query string kept
    assert stats.size_bytes == SAMPLE.stat().st_size == local.stat().st_size
    assert stats.chunks_fetched == stats.chunks_total > 0
    assert stats.fetched_bytes <= stats.size_bytes
    assert stats.fetched_bytes == state.ranged_bytes  # nothing read but by ranges
    expected = audit_log(SAMPLE, None).to_dict()
    got = audit_log(local, None).to_dict()
    expected.pop("log", None), got.pop("log", None)
    assert got["cameras"] == expected["cameras"]


def test_connection_dropped_mid_chunk_is_retried_then_a_read_error(
    http_root: tuple[str, ServerState], tmp_path: Path
) -> None:
    base, state = http_root
    _serve(state.root, "log.mcap", SAMPLE)
    state.drop_after_bytes = 1000
    state.drop_min_length = 1 << 16
    with pytest.raises(
        LogReadError, match=r"log.mcap: reading bytes \d+-\d+ failed 3 times"
    ) as err:
        fetch_log(f"{base}/log.mcap", tmp_path)
    assert err.value.exit_code == 3
    assert len(state.requests) >= 3 + 1
