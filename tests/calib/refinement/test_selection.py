"""Joint, baseline or none (calib.joint_estimate): which estimate a LiDAR gets when the
joint graph leaves a direction of its extrinsic free."""

from __future__ import annotations

import numpy as np

from syncaudit.calib.alignment.registration import Alignment, Conditioning, Fit
from syncaudit.calib.graph.jointgraph import JointSolution
from syncaudit.calib.refinement.joint_estimate import _free_reason, _select
from syncaudit.calib.refinement.maptomap import NOT_CALIBRATED
from syncaudit.calib.result import ExtrinsicOut, FreeDirectionOut, TransformOut
from syncaudit.calib.settings import CalibConfig
from syncaudit.calib.state import LidarState

_UP = np.array([0.0, 0.0, 1.0])
_LIDARS = [
    LidarState("/lidar/front/points", "lidar_front", [], _UP),
    LidarState("/lidar/rear/points", "lidar_rear", [], _UP),
]
_FREE = [FreeDirectionOut(kind="translation", axis=(0.9, 0.44, 0.06), sigma=2.04)]


def _baseline() -> ExtrinsicOut:
    """A baseline that calibrated (its numbers do not enter the choice)."""
    return ExtrinsicOut(
        topic="/lidar/rear/points",
        frame_id="lidar_rear",
        reference_topic="/lidar/front/points",
        reference_frame_id="lidar_front",
        recorded=TransformOut.of(np.eye(4)),
        calibrated=True,
        reason=None,
        map_to_map=None,
        **{**NOT_CALIBRATED, "result": TransformOut.of(np.eye(4)), "passed": True},
    )


def _maps_aligned(overlap: float) -> Alignment:
    conditioning = Conditioning(0.05, 0.01, (0.9, 0.44, 0.06), (0.0, 0.0, 1.0))
    fit = Fit(overlap, 0.032, conditioning, 1000, np.eye(6))
    return Alignment(np.eye(4), True, 7, fit, fit, True, None)


def _choice(*, mapped: bool) -> str:
    solution = JointSolution({}, {1: np.eye(4)}, {1: np.eye(6)}, [], 0.0, 0.0, 0)
    selection = _select(
        _LIDARS, 1, 0, solution, _baseline(), calibrated=False, mapped=mapped, config=CalibConfig()
    )
    return selection.method


def test_a_free_direction_falls_back_to_the_baseline_when_the_maps_never_entered_the_graph() -> (
    None
):
    # The joint graph never aligned the maps (parking-64-open-bumper seed 2: the refinement
    # slid 272 cm and was rejected): the baseline's map-to-map bridge is information the
    # graph lacks, so the baseline stands.
    assert _choice(mapped=False) == "baseline"


def test_a_direction_free_with_the_maps_in_the_graph_calibrates_neither() -> None:
    # The maps aligned on the joint poses and joined the graph, yet a direction stays
    # free: the baseline's only bridge is such an alignment, so it is no firmer there.
    assert _choice(mapped=True) == "none"
    reason = _free_reason(
        _LIDARS[1],
        _FREE,
        {0: [2, 3, 4], 1: [0, 1, 2]},
        [x.topic for x in _LIDARS],
        _maps_aligned(0.2),
    )
    assert "translation along (0.90, 0.44, 0.06) in lidar_rear (1-sigma 2.04 cm)" in reason
    assert "/lidar/rear/points placed stops [0, 1, 2]" in reason
    assert "(overlap 20 %)" in reason and "record more stops" in reason
