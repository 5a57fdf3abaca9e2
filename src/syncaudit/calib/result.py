"""Result of a calibration run: what was used, every alignment's verdict, the extrinsics.

Plain pydantic models so the result serialises to JSON as is (`to_json_dict`).
Infinite errors (nothing overlapped) are stored as null.
"""

from __future__ import annotations

import math
from typing import Any

from pydantic import BaseModel, ConfigDict

from syncaudit.calib import se3
from syncaudit.calib.alignment.registration import Alignment, Conditioning, Fit
from syncaudit.calib.se3 import Mat


class _Out(BaseModel):
    model_config = ConfigDict(frozen=True)


def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None


class TransformOut(_Out):
    """A rigid transform as translation, roll/pitch/yaw, quaternion and 4x4 matrix."""

    translation_m: tuple[float, float, float]
    rpy_deg: tuple[float, float, float]
    quaternion_xyzw: tuple[float, float, float, float]
    matrix: list[list[float]]

    @classmethod
    def of(cls, transform: Mat) -> TransformOut:
        """From a 4x4 matrix."""
        roll, pitch, yaw = se3.matrix_to_rpy(transform[:3, :3])
        tx, ty, tz = (float(v) for v in transform[:3, 3])
        return cls(
            translation_m=(tx, ty, tz),
            rpy_deg=(math.degrees(roll), math.degrees(pitch), math.degrees(yaw)),
            quaternion_xyzw=se3.matrix_to_quaternion(transform[:3, :3]),
            matrix=[[float(v) for v in row] for row in transform],
        )


class FitOut(_Out):
    """Overlap fraction and point-to-plane RMS error (cm; null when nothing overlapped)."""

    overlap: float
    rmse_cm: float | None

    @classmethod
    def of(cls, fit: Fit) -> FitOut:
        """From a registration Fit."""
        return cls(overlap=fit.overlap, rmse_cm=_finite(fit.rmse_m * 100.0))


class ConditioningOut(_Out):
    """Smallest normalised eigenvalues of the point-to-plane Hessian and their directions."""

    translation_information: float
    rotation_information: float
    weakest_translation: tuple[float, float, float]
    weakest_rotation_axis: tuple[float, float, float]

    @classmethod
    def of(cls, cond: Conditioning) -> ConditioningOut:
        """From a registration Conditioning."""
        return cls(
            translation_information=cond.translation_information,
            rotation_information=cond.rotation_information,
            weakest_translation=cond.weakest_translation,
            weakest_rotation_axis=cond.weakest_rotation_axis,
        )


class AlignmentOut(_Out):
    """One GICP alignment: before/after fit, conditioning, verdict."""

    before: FitOut
    after: FitOut
    conditioning: ConditioningOut
    converged: bool
    iterations: int
    accepted: bool
    reason: str | None
    expected_overlap: float | None = None
    """Overlap the two views allow at the seed pose (the overlap test is relative to it)."""

    @classmethod
    def of(cls, alignment: Alignment) -> AlignmentOut:
        """From a registration Alignment."""
        return cls(
            before=FitOut.of(alignment.before),
            after=FitOut.of(alignment.after),
            conditioning=ConditioningOut.of(alignment.after.conditioning),
            converged=alignment.converged,
            iterations=alignment.iterations,
            accepted=alignment.accepted,
            reason=alignment.reason,
            expected_overlap=alignment.expected_overlap,
        )


class StopUse(_Out):
    """Whether one stop's scan of a LiDAR was used, and why not."""

    stop: int
    stamp_ns: int
    static_scans: int
    angle_deg: float | None
    """Turntable angle relative to the reference stop, from the registration chain."""
    used: bool
    reason: str | None


class PairOut(_Out):
    """A cross-scan alignment (target = first stop, source = second stop)."""

    first_stop: int
    second_stop: int
    separation_deg: float
    predicted_overlap: float
    alignment: AlignmentOut
    graph_residual_rotation_deg: float | None = None
    graph_residual_translation_cm: float | None = None
    graph_outlier: bool | None = None


class PoseGraphOut(_Out):
    """Summary of one LiDAR's pose graphs (one per group of connected stops used)."""

    graphs: int
    nodes: int
    edges: int
    outlier_edges: int
    error_before: float
    error_after: float
    iterations: int


class StopPointsOut(_Out):
    """One stop's points of a LiDAR seen from above, in the map frame (decimated)."""

    stop: int
    x_m: list[float]
    y_m: list[float]


class TopViewOut(_Out):
    """A LiDAR's local map from above: every used stop's points placed by its estimated pose.

    For the report's map coloured by stop; decimated to one point per `cell_m` square per
    stop so a session stays a few hundred KB of JSON.
    """

    frame: str
    """What x/y are in, e.g. "base_link at stop 3" (the map's anchor)."""
    cell_m: float
    stops: list[StopPointsOut]


class DegeneracyOut(_Out):
    """The direction a refused scene or alignment does not constrain, for drawing it."""

    kind: str
    """"translation" (the scene slides along `direction`) or "rotation" (about it)."""
    direction: tuple[float, float, float]
    """Unit vector in `frame`."""
    frame: str
    information: float
    """Mean squared constraint along `direction` (0 = none); compare with `limit`."""
    limit: float


class MovingScansOut(_Out):
    """What became of one LiDAR's scans taken while moving (`alignment.moving_scans`)."""

    seen: int
    """Scans of this LiDAR outside its still runs."""
    deskewed: int
    """Of those, the ones deskewed and registered (the still ones at another LiDAR's stop
    need no deskew and are counted in `still_at_stop`)."""
    still_at_stop: int
    """Scans taken inside another LiDAR's still run (the vehicle stood) that this LiDAR's
    run detection missed: they place that stop for this LiDAR."""
    used: int
    """Scans whose alignments joined the joint graph."""
    motion_source: str | None
    """Where the motion over a sweep came from: odometry, or the neighbouring stops'
    poses refined by the moving scans' own registrations."""
    rejected: dict[str, int]
    """Why the others were not used: reason -> scans."""


class LidarOut(_Out):
    """Per-LiDAR part of the result: scans, stops, pairs, pose graph, local map."""

    topic: str
    frame_id: str
    scans: int
    horizontal_fov_deg: float | None
    turn_axis: tuple[float, float, float] | None = None
    """The turntable axis in this LiDAR's frame, estimated from its alignments (planar model)."""
    turn_axis_vs_recorded_deg: float | None = None
    """Angle between that axis and the base's z axis per the recorded extrinsic: the recorded
    roll/pitch error relative to the floor, independent of the map-to-map step."""
    stops: list[StopUse]
    pairs: list[PairOut]
    pose_graph: PoseGraphOut | None
    map_points: int
    aligned: bool
    reason: str | None
    top_view: TopViewOut | None = None
    """This LiDAR's used stops from above (None when no stop was placed)."""
    moving_scans: MovingScansOut | None = None
    """Its scans taken while moving: seen, deskewed, used, rejected (None: not reached)."""


class MapPairOut(_Out):
    """One map-to-map alignment: both LiDARs' local maps anchored at the same stop."""

    anchor_stop: int
    reference_stops: list[int]
    lidar_stops: list[int]
    alignment: AlignmentOut
    result: TransformOut | None


class ExtrinsicOut(_Out):
    """Calibrated vs recorded `reference_from_lidar`, with the pass/fail verdict."""

    topic: str
    frame_id: str
    reference_topic: str
    reference_frame_id: str
    calibrated: bool
    reason: str | None
    recorded: TransformOut
    result: TransformOut | None
    rotation_diff_deg: float | None
    translation_diff_cm: float | None
    diff_rpy_deg: tuple[float, float, float] | None
    diff_xyz_cm: tuple[float, float, float] | None
    passed: bool
    map_to_map: AlignmentOut | None
    """The map pair at the main anchor stop."""
    map_pairs: list[MapPairOut] = []
    """Every map pair; accepted ones are fused (weighted by their information) into `result`."""
    estimate_spread_deg: float | None = None
    estimate_spread_cm: float | None = None
    """Largest rotation / translation of an accepted map pair's estimate from `result`."""
    stop_angle_disagreement_deg: float | None
    """Largest difference of the vehicle's turn angle as seen by this and the reference LiDAR."""
    hand_eye_rotation_residual_deg: float | None
    """Largest rotation misfit of A X = X B over common stops with the calibrated X."""


class FreeDirectionOut(_Out):
    """A direction of an extrinsic the joint graph leaves looser than the limits."""

    kind: str
    """"rotation" (about `axis`) or "translation" (along `axis`)."""
    axis: tuple[float, float, float]
    """Unit vector in the LiDAR's frame."""
    sigma: float
    """1-sigma of the joint graph along it, deg or cm."""


class JointLidarOut(_Out):
    """One LiDAR's extrinsic from the joint graph and what constrained it."""

    extrinsic: ExtrinsicOut
    sigma_deg: float
    sigma_cm: float
    """Largest 1-sigma of the rotation (deg) and translation (cm) of the joint estimate."""
    free_directions: list[FreeDirectionOut] = []
    scan_links: int
    """This LiDAR's cross-scan alignments in the graph."""
    stops: list[int]
    """Stops this LiDAR's alignments place."""
    refinement: AlignmentOut | None
    """Map-to-map GICP on the joint poses, seeded by the joint estimate (a factor when
    accepted)."""


class SelectionOut(_Out):
    """Which estimate one LiDAR's extrinsic comes from, and the data that chose it."""

    topic: str
    method: str
    """"joint", "baseline" or "none" (the joint graph, with the two maps' alignment in it,
    leaves a direction free: the LiDAR is not calibrated)."""
    criterion: str
    """How the method was chosen (never from a truth: the map costs, or why not them)."""
    joint_map_cost_m2: float | None
    baseline_map_cost_m2: float | None
    """Two-way truncated point-to-plane cost of the two LiDARs' maps on each estimate's
    own poses, over the stops both estimates placed (`calib.map_consistency`)."""


class VehicleUpOut(_Out):
    """The axis the joint graph's planar prior keeps the vehicle turning about."""

    source: str
    """"turn axis", "ground plane" or "recorded" (`calib.vehicle_up`)."""
    axis: tuple[float, float, float]
    """Unit vector in the reference LiDAR's frame."""
    turn_axis_error_deg: float | None
    ground_spread_deg: float | None


class JointOut(_Out):
    """The joint graph: every LiDAR's stop alignments and the extrinsics solved together."""

    chosen: bool
    """Whether `extrinsics` holds this estimate for every LiDAR (`selection` says which
    estimate each LiDAR's comes from)."""
    stops: list[int]
    """Vehicle stops the graph placed."""
    links: dict[str, int]
    """Factors by kind: scan (cross-scan alignments), map (refinements), odometry, ground."""
    lidars: list[JointLidarOut]
    error_before: float
    error_after: float
    iterations: int
    reason: str | None
    """Why it could not calibrate (free directions, by which stops), or None."""
    selection: list[SelectionOut] = []
    """Per LiDAR, the estimate `extrinsics` holds and why."""
    refinement_rounds: int = 0
    up: VehicleUpOut | None = None
    """The vehicle's up the planar prior used, and why."""
    """Map-to-map refinements of the joint poses solved before they stopped moving."""


class VehicleStopOut(_Out):
    """A vehicle stop and which LiDAR topics have static scans there."""

    index: int
    start_ns: int
    end_ns: int
    topics: list[str]


class Limits(_Out):
    """Validation limits."""

    max_rotation_deg: float
    max_translation_cm: float


class CalibrationResult(_Out):
    """Everything `calibrate_log` found; `passed` only when calibratable and within limits."""

    kind: str = "syncaudit.calibration"
    log: str
    calibratable: bool
    reason: str | None
    passed: bool
    reference_topic: str
    reference_frame_id: str
    base_frame: str
    extrinsics_source: str
    reference_stop: int | None
    anchor_stops: list[int] = []
    """Stops at which local maps were anchored and aligned (the first is `reference_stop`)."""
    limits: Limits
    degeneracy: DegeneracyOut | None = None
    """Set when the scene was refused as degenerate: the free direction, structured."""
    stops: list[VehicleStopOut]
    lidars: list[LidarOut]
    extrinsics: list[ExtrinsicOut]
    """The chosen estimate per LiDAR: the joint graph's when it calibrated, else the
    baseline's (per-LiDAR graphs bridged by map-to-map GICP)."""
    baseline: list[ExtrinsicOut] = []
    """The per-LiDAR pipeline's estimate (kept as the baseline the joint one is judged by)."""
    joint: JointOut | None = None
    notes: list[str]
    timings_s: dict[str, float]
    libraries: dict[str, str]
    reference_mount: TransformOut | None = None
    """The reference LiDAR's recorded pose on the vehicle (base_from_reference): with it the
    report places every mount on a map drawn in the base frame."""

    def to_json_dict(self) -> dict[str, Any]:
        """The result as plain JSON types."""
        return self.model_dump(mode="json")
