"""HTTP redirects on ranged reads, against real loopback servers that issue them."""

from __future__ import annotations

import base64
from pathlib import Path

import pytest

from syncaudit.audit.run import audit_log
from syncaudit.errors import LogReadError
from syncaudit.logs import open_log
from syncaudit.remote.ranges import MAX_REDIRECTS
from syncaudit.rig import load_rig

from .conftest import ServerState, fetched

REPO = Path(__file__).resolve().parents[2]
SAMPLES = REPO / "sample_logs"
NAME = "vlp16_three_cameras.mcap"


def _without_path(result: object) -> dict[str, object]:
    data: dict[str, object] = result.to_dict()  # type: ignore[attr-defined]
    data.pop("path", None)
    return data


@pytest.mark.parametrize("status", [301, 302, 303, 307, 308])
def test_a_redirected_log_audits_as_the_local_file(
    http_root: tuple[str, ServerState], status: int
) -> None:
    base, state = http_root
    (state.root / NAME).symlink_to(SAMPLES / NAME)
    state.redirects[f"/old/{NAME}"] = (status, f"/{NAME}")  # relative Location
    rig = load_rig(SAMPLES / f"{NAME}.rig.yaml")
    url = f"{base}/old/{NAME}"
    with open_log(url) as log:  # its fetch statistics cover the audit's own open
        remote = audit_log(url, rig, jobs=2)
        stats = fetched(log)
    assert _without_path(remote) == _without_path(audit_log(SAMPLES / NAME, rig, jobs=2))
    assert remote.to_dict()["path"] == url  # the log keeps the name it was given
    ranged = [r for r in state.requests if r.startswith(f"/{NAME} bytes=")]
    asked = [r for r in state.requests if r.startswith("/old/")]
    assert ranged and all(" bytes=" in r for r in asked)  # the Range went along
    if status in (301, 308):  # permanent: later ranges go straight to the new place
        assert len(asked) <= 3  # the first open of the parent, and one per forked worker
    else:  # temporary: every range asks the old place first
        assert len(asked) == len(ranged)
    assert stats["fetched_bytes"] == state.served_bytes  # redirect replies carry no body


def test_credentials_go_to_their_own_host_only(
    http_root: tuple[str, ServerState], other_http_root: tuple[str, ServerState]
) -> None:
    base, state = http_root
    other_base, other = other_http_root
    (state.root / NAME).symlink_to(SAMPLES / NAME)
    (other.root / NAME).symlink_to(SAMPLES / NAME)
    port = base.rsplit(":", 1)[1]
    # Same host: the second hop keeps the credentials; then off to another host.
    state.redirects[f"/a/{NAME}"] = (302, f"/b/{NAME}")
    state.redirects[f"/b/{NAME}"] = (307, f"{other_base.replace('127.0.0.1', 'localhost')}/{NAME}")
    with open_log(f"http://user:p%40ss@127.0.0.1:{port}/a/{NAME}") as log:
        assert log.summary.path == f"http://127.0.0.1:{port}/a/{NAME}"  # no user info
        assert log.topics  # the index was read across both redirects
    want = "Basic " + base64.b64encode(b"user:p@ss").decode()
    assert {auth for _, auth in state.authorizations} == {want}
    assert other.authorizations and {auth for _, auth in other.authorizations} == {None}


def test_a_redirect_loop_is_a_read_error_naming_the_url(
    http_root: tuple[str, ServerState],
) -> None:
    base, state = http_root
    state.redirects[f"/{NAME}?sig=secret"] = (302, f"/x/{NAME}?sig=other-secret")
    state.redirects[f"/x/{NAME}?sig=other-secret"] = (302, f"/{NAME}?sig=secret")
    with pytest.raises(LogReadError, match=rf"more than {MAX_REDIRECTS} redirects") as err:
        open_log(f"{base}/{NAME}?sig=secret")
    assert err.value.exit_code == 3
    assert "secret" not in str(err.value)
    assert len(state.requests) == MAX_REDIRECTS + 1  # no retry of what no retry changes


def test_a_redirect_without_location_or_to_another_scheme_is_refused(
    http_root: tuple[str, ServerState],
) -> None:
    base, state = http_root
    state.redirects[f"/{NAME}"] = (301, "ftp://example.org/log.mcap")
    with pytest.raises(LogReadError, match="redirect to a ftp: URL"):
        open_log(f"{base}/{NAME}")
    state.redirects[f"/{NAME}"] = (302, "")
    with pytest.raises(LogReadError, match="HTTP 302 redirect without a Location"):
        open_log(f"{base}/{NAME}")
