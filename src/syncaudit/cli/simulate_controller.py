"""The self-adaptive delay controller run live inside the sync simulator (`--controller`).

The simulator imports nothing it is used to check, so it takes its changing delays from
its caller (`syncaudit.simulate.delays.LiveDelays`); this wraps `analysis.controller` so.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from syncaudit.analysis.controller import ControllerConfig, DelayController, FrameObservation
from syncaudit.simulate.delays import DelayChange, FrameTiming


class _CameraController:
    """One camera's `DelayController`, speaking the simulator's frame and change records."""

    def __init__(self, config: ControllerConfig, initial_delay_ns: int) -> None:
        self._controller = DelayController(config, initial_delay_ns=initial_delay_ns)

    def update(self, frame: FrameTiming) -> tuple[int, Sequence[DelayChange]]:
        """The controller's next delay after `frame`, and the adjustments it made."""
        before = len(self._controller.adjustments)
        delay = self._controller.update(
            FrameObservation(
                t1_ns=frame.t1_ns,
                t2_ns=frame.t2_ns,
                t3_ns=frame.t3_ns,
                t4_ns=frame.t4_ns,
                exposure_ns=frame.exposure_ns,
                error_ns=frame.error_ns,
                t_rotate_ns=frame.t_rotate_ns,
            )
        )
        changes = [
            DelayChange(
                after_frame_sequence=adj.frame_index,
                old_delay_ns=adj.old_delay_ns,
                new_delay_ns=adj.new_delay_ns,
                reason=adj.reason,
                window_error_mean_ns=adj.stats.error_mean_ns,
                window_error_var_ns2=adj.stats.error_var_ns2,
            )
            for adj in self._controller.adjustments[before:]
        ]
        return delay, changes


class ControllerDelays:
    """`LiveDelays` of the project's controller with `config` (defaults: `ControllerConfig()`)."""

    def __init__(self, config: ControllerConfig | None = None) -> None:
        self.config = config if config is not None else ControllerConfig()

    @property
    def settings(self) -> dict[str, Any]:
        """The controller's settings as the truth records them."""
        return self.config.model_dump(mode="json")

    @property
    def window_frames(self) -> int:
        """N of Eq. 3: the controller's t5 window."""
        return self.config.window_frames

    def for_camera(self, initial_delay_ns: int) -> _CameraController:
        """A fresh controller for one camera."""
        return _CameraController(self.config, initial_delay_ns)
