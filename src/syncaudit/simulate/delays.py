"""Where the simulated cameras' applied trigger delays come from: constant, or a caller's policy.

The simulator checks nothing, so it does not run the project's delay controller
(`syncaudit.analysis.controller`, which the audit replays and which a simulated log is
used to test). A caller that wants delays changing frame by frame passes a `LiveDelays`:
per camera, an object told what the camera driver measured for each frame and answering
the delay of the next one (the CLI wraps the controller so). Without one, every frame of
a camera gets the same delay.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

CONSTANT_WINDOW_FRAMES = 10
"""The window (frames) the truth names for its t5 average when the delays are constant:
the controller's default N (tests/simulate/test_sync_log.py holds the two equal)."""


@dataclass(frozen=True, slots=True)
class FrameTiming:
    """What the camera driver measured for one frame (integer ns), as a live policy sees it."""

    t1_ns: int
    """240 -> 242: packet captured -> LiDAR driver."""
    t2_ns: int
    """242 -> 244: LiDAR driver -> camera driver."""
    t3_ns: int
    """244 -> 246 minus the applied delay: camera driver -> camera sensor."""
    t4_ns: int
    """246 -> 248: camera told -> exposure starts."""
    exposure_ns: int
    """t5_i, the frame's exposure duration."""
    error_ns: int
    """Signed synchronisation error t_l - t_estimated (positive: camera late)."""
    t_rotate_ns: int
    """theta / omega for this camera, as measured for this revolution."""


@dataclass(frozen=True, slots=True)
class DelayChange:
    """One change of a camera's delay, as the truth records it (the field order is the JSON's)."""

    after_frame_sequence: int
    old_delay_ns: int
    new_delay_ns: int
    reason: str
    window_error_mean_ns: float
    window_error_var_ns2: float


class CameraDelays(Protocol):
    """One camera's live delay policy."""

    def update(self, frame: FrameTiming) -> tuple[int, Sequence[DelayChange]]:
        """The delay (ns) for the next frame after `frame`, and the changes this frame made."""
        ...


class LiveDelays(Protocol):
    """A delay policy run live on every camera, supplied by the simulator's caller."""

    @property
    def settings(self) -> dict[str, Any]:
        """Plain-JSON settings, recorded in the truth's config as `controller`."""
        ...

    @property
    def window_frames(self) -> int:
        """The window (frames) the policy averages t5 over (the truth's t5_window_frames)."""
        ...

    def for_camera(self, initial_delay_ns: int) -> CameraDelays:
        """A fresh policy for one camera that starts at `initial_delay_ns`."""
        ...
