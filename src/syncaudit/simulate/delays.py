"""Where the simulated cameras' applied trigger delays come from: constant, compensated, or a
caller's policy.

The simulator checks nothing, so it does not run the project's delay controller
(`syncaudit.analysis.controller`, which the audit replays and which a simulated log is
used to test). A caller that wants delays changing frame by frame passes a `LiveDelays`:
per camera, an object told what the camera driver measured for each frame and answering
the delay of the next one (the CLI wraps the controller so). `CompensatedDelays` is the
simulator's own ideal per-frame compensation: each frame's delay takes its own exposure's
half off, as a rig with exact exposure feed-forward does. Without either, every frame of a
camera gets the same delay.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

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


@dataclass(frozen=True, slots=True)
class CompensatedDelays:
    """Each frame's delay compensates its own exposure exactly (ideal exposure feed-forward).

    Frame i is triggered with `initial + t5_mean / 2 - t5_i / 2`: the camera's constant
    delay (the ideal mean plus its `delay_error_us`) with the log's mean half exposure
    replaced by the frame's own. What a rig that knows the exposure the camera is about to
    use applies; the error left is the trigger chain's jitter and the packet quantisation,
    plus the camera's `delay_error_us`.
    """

    @property
    def settings(self) -> dict[str, Any]:
        """What the truth records under `config.controller`."""
        return {"policy": "compensated", "exposure": "each frame's own, exactly"}

    @property
    def window_frames(self) -> int:
        """No t5 window is used; the truth names the constant delays' one."""
        return CONSTANT_WINDOW_FRAMES

    def applied_ns(self, initial_ns: int, exposure_ns: NDArray[np.int64]) -> NDArray[np.int64]:
        """Every frame's delay (ns, never negative) from the camera's constant `initial_ns`."""
        half_mean = round(float(exposure_ns.mean()) / 2.0) if exposure_ns.size else 0
        applied: NDArray[np.int64] = np.maximum(
            0, initial_ns + half_mean - exposure_ns.astype(np.int64) // 2
        )
        return applied
