"""Remote MCAP reads over a real loopback HTTP server: ranged, sparse, retried, audited."""

from __future__ import annotations

from pathlib import Path

import pytest

from syncaudit.audit.run import audit_log
from syncaudit.errors import LogReadError
from syncaudit.remote.fetch import coalesce, fetch_log
from syncaudit.remote.urls import public_url

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


def _per_topic_mcap(path: Path) -> dict[str, list[bytes]]:
    """An MCAP (official writer, zstd chunks of ~64 KiB) whose topics sit in separate chunks:
    all of /wanted's messages, then all of /other's, as a recorder splitting by topic or
    time would leave them. Returns the payloads written per topic."""
    from mcap.writer import CompressionType, Writer

    written: dict[str, list[bytes]] = {"/wanted": [], "/other": []}
    with path.open("wb") as handle:
        writer = Writer(handle, chunk_size=64 << 10, compression=CompressionType.ZSTD)
        writer.start("ros2", "syncaudit-test")
        schema = writer.register_schema("std_msgs/msg/Int32", "ros2msg", b"int32 data")
        channels = {
            topic: writer.register_channel(topic, "cdr", schema) for topic in ("/wanted", "/other")
        }
        rng = __import__("random").Random(7)
        for topic, count in (("/wanted", 300), ("/other", 2000)):
            for index in range(count):
                payload = rng.randbytes(1000)  # incompressible: chunk sizes stay honest
                writer.add_message(channels[topic], index, payload, index)
                written[topic].append(payload)
        writer.finish()
    return written


def test_only_chunks_of_audited_topics_are_fetched(
    http_root: tuple[str, ServerState], tmp_path: Path
) -> None:
    from mcap.reader import make_reader

    base, state = http_root
    source = tmp_path / "split.mcap"
    written = _per_topic_mcap(source)
    (state.root / "split.mcap").symlink_to(source)
    (tmp_path / "copy").mkdir()
    local, stats = fetch_log(f"{base}/split.mcap", tmp_path / "copy", topics=frozenset({"/wanted"}))
    with source.open("rb") as handle:
        summary = make_reader(handle).get_summary()
    assert summary is not None
    wanted_id = next(c.id for c in summary.channels.values() if c.topic == "/wanted")
    holding = [c for c in summary.chunk_indexes if wanted_id in c.message_index_offsets]
    assert 0 < stats.chunks_fetched == len(holding) < stats.chunks_total
    assert stats.needed_chunk_bytes == sum(c.chunk_length for c in holding)
    assert stats.fetched_bytes == state.ranged_bytes
    assert stats.fetched_bytes <= 1.05 * stats.needed_chunk_bytes + 128 * 1024  # + head, summary
    assert stats.fetched_bytes < 0.25 * stats.size_bytes
    # The sparse copy reads back /wanted exactly, through its index.
    with local.open("rb") as handle:
        got = [m.data for _, _, m in make_reader(handle).iter_messages(topics=["/wanted"])]
    assert got == written["/wanted"]
