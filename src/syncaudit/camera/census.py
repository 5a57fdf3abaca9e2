"""Which camera each message of a topic several cameras share goes to, counted for `info`.

`info` shows a topic shared by several cameras (one driver node for a multi-camera board)
as those cameras, with the messages each gets. The count runs the audit's own reading
(`logs.parallel.iter_items` with the camera rows of `camera.frame_rows`) and routing
(`camera.routing.CameraRouter`) over the shared topics only, so `info` and `audit`
cannot disagree on which camera a message belongs to.
"""

from __future__ import annotations

from dataclasses import dataclass

from syncaudit.camera.frame_rows import CameraRowExtractor
from syncaudit.camera.routing import CameraRouter, SharedTopicCount
from syncaudit.errors import LogReadError
from syncaudit.logs import LogReader
from syncaudit.logs.parallel import iter_items
from syncaudit.rig import CameraConfig

__all__ = ["SharedCensus", "shared_topic_census"]


@dataclass(frozen=True, slots=True)
class SharedCensus:
    """The shared topics of a set of cameras, counted, and what the audit would warn."""

    topics: list[SharedTopicCount]
    warnings: list[str]


def shared_topic_census(
    log: LogReader, cameras: list[CameraConfig], *, jobs: int = 1
) -> SharedCensus:
    """Count, per topic several of `cameras` read, the messages each camera gets.

    Reads only those topics, as the audit reads them (`logs.parallel.iter_items`: `jobs` worker
    processes where the log allows; of an image, only its header's first bytes).
    A topic whose every message is damaged is reported as a warning, as far as counted.
    """
    router = CameraRouter.for_cameras(cameras, log.topics)
    shared = {(kind, topic) for kind, topics in _by_kind(router).items() for topic in topics}
    if not shared:
        return SharedCensus([], [])
    # A shared topic's owner is "": the router gives each row to the camera it names.
    rows = CameraRowExtractor(
        images={t: "" for k, t in shared if k == "image"},
        exposures={t: ("", _stamp(router, t)) for k, t in shared if k == "exposure"},
        triggers={t: "" for k, t in shared if k == "trigger"},
    )
    for kind, topic, payload in iter_items(log, rows, jobs):
        router.feed(kind, topic, payload)
    try:
        warnings = router.finish()
    except LogReadError as exc:
        warnings = [str(exc)]
    return SharedCensus(router.shared_counts(), warnings)


def _by_kind(router: CameraRouter) -> dict[str, list[str]]:
    """Per kind, the topics more than one camera reads."""
    return {
        kind: [t for t, owners in router.topics(kind).items() if len(owners) > 1]
        for kind in ("image", "exposure", "trigger")
    }


def _stamp(router: CameraRouter, topic: str) -> str:
    """Stamp semantics of the first camera reading an exposure topic (as the audit's plan)."""
    return router.topics("exposure")[topic][0].camera.stamp
