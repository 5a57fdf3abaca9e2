"""`remote.file`: a remote object as a seekable file, shared by every open of it in a process."""

from __future__ import annotations

from syncaudit.logs import open_log
from syncaudit.remote.file import RemoteFile, shared_source

from .conftest import SAMPLES, ServerState, fetched


def test_reads_and_holds_are_the_objects_bytes_and_holds_join(
    http_root: tuple[str, ServerState],
) -> None:
    base, state = http_root
    data = bytes(range(256)) * 64
    (state.root / "blob").write_bytes(data)
    file = RemoteFile.open(f"{base}/blob", 16)
    try:
        assert file.size == len(data) and file.read(16) == data[:16]
        file.hold(1000, 2000)
        file.hold(500, 1000)  # joined to the segment at 1000: one read across both
        asked = len(state.requests)
        assert bytes(file.held(600, 1900) or b"") == data[600:1900]
        file.seek(700)
        assert file.read(1200) == data[700:1900] and len(state.requests) == asked
        file.seek(-10, 2)
        assert file.read() == data[-10:]  # a miss: fetched
        assert len(state.requests) == asked + 1
        assert file.source.stats().fetched_bytes == state.ranged_bytes
    finally:
        file.close()
    assert shared_source(f"{base}/blob") is None


def test_a_second_open_reuses_what_the_first_fetched_until_the_last_close(
    http_root: tuple[str, ServerState],
) -> None:
    base, state = http_root
    name = "vlp16_three_cameras.mcap"
    (state.root / name).symlink_to(SAMPLES / name)
    url = f"{base}/{name}?sig=s3cr3t"
    with open_log(url) as first:
        asked = len(state.requests)
        assert asked >= 2  # head, then the tail and summary ahead
        with open_log(url) as second:
            assert len(state.requests) == asked  # the index from the first open's bytes
            assert fetched(second) == fetched(first)
        assert shared_source(f"{base}/{name}") is not None  # the first is still open
    assert shared_source(f"{base}/{name}") is None
