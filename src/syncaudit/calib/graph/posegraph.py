"""Per-LiDAR pose graph (gtsam): global alignment of the accepted cross-scan alignments.

Nodes are the LiDAR's poses at the stops, anchored at the reference stop (identity), so
the optimised poses place every scan in the LiDAR's frame at the reference stop. Edges
are the accepted pair alignments, each weighted by its own point-to-plane Hessian (a
direction the scene barely constrains carries little weight) under a robust kernel, so
one bad edge cannot drag the graph; edges whose whitened residual exceeds
`max_edge_residual_sigmas` are reported as outliers.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from syncaudit.calib import se3
from syncaudit.calib.settings import PoseGraphConfig
from syncaudit.errors import MissingExtraError

F64 = NDArray[np.float64]


def backend() -> ModuleType:
    """The gtsam module, or a one-line MissingExtraError (exit 64) naming the extra to install."""
    try:
        import gtsam
    except ImportError:
        raise MissingExtraError(
            "LiDAR calibration needs the optional extra: pip install 'syncaudit[calib]' "
            "(gtsam is missing)"
        ) from None
    return gtsam


@dataclass(frozen=True)
class Edge:
    """A measured relative pose `first_from_second` between two stops, with its weight."""

    first: int
    second: int
    first_from_second: F64
    hessian: F64
    """Mean point-to-plane Hessian of the alignment (6x6, gtsam's [rotation, translation]
    body-frame tangent at the second pose)."""
    strength: float
    """Smallest normalised information (translation or rotation) of the alignment."""


@dataclass(frozen=True)
class EdgeResidual:
    """How far the optimised poses are from one edge's measurement."""

    first: int
    second: int
    rotation_deg: float
    translation_cm: float
    sigmas: float
    outlier: bool


@dataclass(frozen=True)
class PoseGraphSolution:
    """Optimised poses (reference frame = the anchor stop) and the per-edge residuals."""

    poses: dict[int, F64]
    residuals: list[EdgeResidual]
    error_before: float
    error_after: float
    iterations: int


def connected(nodes: Iterable[int], edges: Iterable[Edge], anchor: int) -> set[int]:
    """Stops reachable from `anchor` through `edges` (the only ones the graph can place)."""
    adjacency: dict[int, set[int]] = {n: set() for n in nodes}
    for edge in edges:
        adjacency.setdefault(edge.first, set()).add(edge.second)
        adjacency.setdefault(edge.second, set()).add(edge.first)
    seen = {anchor}
    todo = [anchor]
    while todo:
        node = todo.pop()
        for nxt in adjacency.get(node, ()):
            if nxt not in seen:
                seen.add(nxt)
                todo.append(nxt)
    return seen


def _pose3(gtsam: Any, transform: F64) -> Any:
    return gtsam.Pose3(np.ascontiguousarray(transform, dtype=np.float64))


def information(edge: Edge, sigma_m: float) -> F64:
    """Edge information: its mean Hessian over sigma^2, regularised to stay invertible."""
    info = edge.hessian / sigma_m**2
    return np.asarray(info + np.eye(6) * 1e-9 * max(float(np.trace(info)), 1.0))


def spanning_poses(anchor: int, edges: list[Edge]) -> dict[int, F64]:
    """Initial poses along a maximum-strength spanning tree grown from the anchor (Prim)."""
    poses = {anchor: np.eye(4)}
    while True:
        frontier = [e for e in edges if (e.first in poses) != (e.second in poses)]
        if not frontier:
            return poses
        edge = max(frontier, key=lambda e: e.strength)
        if edge.first in poses:
            poses[edge.second] = poses[edge.first] @ edge.first_from_second
        else:
            poses[edge.first] = poses[edge.second] @ se3.invert(edge.first_from_second)


def turn_axis(edges: list[Edge], hint: F64, min_angle_deg: float = 5.0) -> F64 | None:
    """The turntable axis in the LiDAR frame, from the rotation axes of the alignments.

    Every relative pose of a LiDAR between two stops of a turning vehicle is a rotation
    about the same axis (the vehicle's vertical, seen from the LiDAR), so the axes of the
    measured rotations estimate it without using the recorded extrinsic; `hint` (the
    recorded up vector) only fixes the sign. Rotation vectors are summed, which weights
    larger, better-defined turns more. An alignment whose rotation tilts out of the plane
    of motion far more than the others' (`tilting_edges`) is no turn of the vehicle and is
    left out. None when no alignment turned enough.
    """
    rotvecs = _turn_vectors(edges, hint, min_angle_deg)
    axis = _summed_axis(list(rotvecs.values()))
    return None if axis is None else _without_tilting(rotvecs, axis)[1]


_MIN_TILT_OUTLIER_DEG = 0.1
_TILT_OUTLIER_FACTOR = 5.0
"""An alignment tilts out of the plane of motion when the part of its rotation across the
turn axis exceeds both `_MIN_TILT_OUTLIER_DEG` (the 32/64-beam rotation target) and
`_TILT_OUTLIER_FACTOR` times the median of the others' (their noise, larger on sparse
LiDARs). Leaving out a correct alignment costs the axis little (it is summed over all
firm ones); keeping a wrong one tilts every planar pose. Measured on bumper 64-beam drives:
correct firm alignments tilted 0.005-0.06 deg; an accepted 8->10 one at 11 % overlap
tilted 0.89 deg (0.84 deg / 3.7 cm off) and, summed with its 69 deg turn, moved the axis by
0.08 deg, which tilted the planar graph's far stops by 0.16 deg / 1 cm and the
calibration by 1.06 cm (seed 17); on seed 13 a 0-9 and a 7-9 one (2.2 and 3.1 cm off)
tilted 0.40 and 0.23 deg, and leaving out only the first moved the axis from 0.019 to
0.035 deg off (their tilts had partly cancelled), both 0.004 deg."""


def _turn_vectors(edges: list[Edge], hint: F64, min_angle_deg: float) -> dict[tuple[int, int], F64]:
    out = {}
    for edge in edges:
        rotvec = se3.log_so3(edge.first_from_second[:3, :3])
        if math.degrees(float(np.linalg.norm(rotvec))) < min_angle_deg:
            continue
        out[(edge.first, edge.second)] = rotvec if float(rotvec @ hint) >= 0 else -rotvec
    return out


def _summed_axis(rotvecs: list[F64]) -> F64 | None:
    """The unit axis of the summed rotation vectors (None: nothing turned)."""
    total = np.sum(rotvecs, axis=0) if rotvecs else np.zeros(3)
    norm = float(np.linalg.norm(total))
    return None if norm == 0.0 else np.asarray(total / norm, dtype=np.float64)


def tilting_edges(
    edges: list[Edge], axis: F64, hint: F64, min_angle_deg: float = 5.0
) -> list[tuple[int, int]]:
    """Alignments whose rotation tilts out of the plane of motion about `axis` (a planar
    vehicle's turns cannot tilt), worst first, each judged against the rest's axis.

    The worst one is removed and the axis re-estimated while the worst tilt exceeds the
    limits above, so one bad alignment neither hides behind the axis it pulled nor makes
    correct ones look tilted."""
    return _without_tilting(_turn_vectors(edges, hint, min_angle_deg), axis)[0]


def _without_tilting(
    rotvecs: dict[tuple[int, int], F64], axis: F64
) -> tuple[list[tuple[int, int]], F64]:
    """(`tilting_edges`, the axis of the turns left), removing the worst tilt at a time."""
    out: list[tuple[int, int]] = []
    current = axis
    while len(rotvecs) > 2:
        tilts = {
            key: math.degrees(float(np.linalg.norm(v - (v @ current) * current)))
            for key, v in rotvecs.items()
        }
        worst = max(tilts, key=lambda k: tilts[k])
        others = [t for k, t in tilts.items() if k != worst]
        limit = max(_MIN_TILT_OUTLIER_DEG, _TILT_OUTLIER_FACTOR * float(np.median(others)))
        if tilts[worst] <= limit:
            break
        rest = {k: v for k, v in rotvecs.items() if k != worst}
        rest_axis = _summed_axis(list(rest.values()))
        if rest_axis is None:
            break
        out.append(worst)
        rotvecs, current = rest, rest_axis
    return out, current


@dataclass(frozen=True)
class _Plane:
    """Frame change that maps the turn axis onto z, so stop poses become SE(2) poses."""

    to_plane: F64

    @classmethod
    def about(cls, axis: F64) -> _Plane:
        z = np.array([0.0, 0.0, 1.0])
        cross = np.cross(axis, z)
        angle = math.atan2(float(np.linalg.norm(cross)), float(axis @ z))
        rot = np.eye(3) if angle < 1e-12 else se3.axis_angle_about(cross, angle)
        return cls(se3.make_transform(rot, (0.0, 0.0, 0.0)))

    def pose2(self, gtsam: Any, transform: F64) -> Any:
        """The planar part (x, y, yaw) of a relative pose seen in the plane frame."""
        t = self.to_plane @ transform @ se3.invert(self.to_plane)
        return gtsam.Pose2(
            float(t[0, 3]), float(t[1, 3]), math.atan2(float(t[1, 0]), float(t[0, 0]))
        )

    def pose3(self, pose2: Any) -> F64:
        """A planar pose back in the LiDAR frame: rotation about the axis, shift across it."""
        planar = se3.make_transform(
            se3.rot_z(float(pose2.theta())), (float(pose2.x()), float(pose2.y()), 0.0)
        )
        return np.asarray(se3.invert(self.to_plane) @ planar @ self.to_plane)

    def information(self, info6: F64) -> F64:
        """Information on (x, y, yaw) in the plane frame from a 6x6 [rotation, translation] one,
        holding the out-of-plane motion fixed (the model says it is zero)."""
        rot = self.to_plane[:3, :3]
        big = np.zeros((6, 6))
        big[:3, :3] = rot
        big[3:, 3:] = rot
        info = big @ info6 @ big.T
        pick = [3, 4, 2]
        return np.asarray(info[np.ix_(pick, pick)])


def _kernel(gtsam: Any, config: PoseGraphConfig) -> Any:
    if config.kernel == "cauchy":
        return gtsam.noiseModel.mEstimator.Cauchy.Create(config.kernel_width)
    return gtsam.noiseModel.mEstimator.Huber.Create(config.kernel_width)


def _residuals(
    gtsam: Any,
    edges: list[Edge],
    poses: dict[int, F64],
    config: PoseGraphConfig,
    plane: _Plane | None,
) -> list[EdgeResidual]:
    out = []
    for edge in edges:
        predicted = se3.invert(poses[edge.first]) @ poses[edge.second]
        rot_deg, trans_m = se3.transform_difference(edge.first_from_second, predicted)
        info = information(edge, config.edge_sigma_m)
        if plane is None:
            delta = se3.invert(edge.first_from_second) @ predicted
            xi = np.asarray(gtsam.Pose3.Logmap(_pose3(gtsam, delta)), dtype=np.float64)
        else:
            measured = plane.pose2(gtsam, edge.first_from_second)
            xi = np.asarray(
                gtsam.Pose2.Logmap(measured.between(plane.pose2(gtsam, predicted))),
                dtype=np.float64,
            )
            info = plane.information(info)
        whitened = math.sqrt(max(float(xi @ info @ xi), 0.0))
        out.append(
            EdgeResidual(
                first=edge.first,
                second=edge.second,
                rotation_deg=rot_deg,
                translation_cm=trans_m * 100.0,
                sigmas=whitened,
                outlier=whitened > config.max_edge_residual_sigmas,
            )
        )
    return out


def optimise(
    anchor: int,
    initial: dict[int, F64],
    edges: list[Edge],
    config: PoseGraphConfig,
    axis: F64 | None = None,
) -> PoseGraphSolution:
    """Levenberg-Marquardt over `initial` poses with robust between-factors for `edges`.

    With `axis` the stop poses are planar (SE(2) about the turn axis, gtsam Pose2), else
    free (SE(3), gtsam Pose3). Residuals are reported for `edges`; edges beyond the limit
    are outliers.
    """
    gtsam = backend()
    kernel = _kernel(gtsam, config)
    plane = None if axis is None else _Plane.about(axis)
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    if plane is None:
        graph.add(
            gtsam.PriorFactorPose3(
                anchor, _pose3(gtsam, initial[anchor]), gtsam.noiseModel.Isotropic.Sigma(6, 1e-6)
            )
        )
        for edge in edges:
            noise = gtsam.noiseModel.Gaussian.Information(information(edge, config.edge_sigma_m))
            graph.add(
                gtsam.BetweenFactorPose3(
                    edge.first,
                    edge.second,
                    _pose3(gtsam, edge.first_from_second),
                    gtsam.noiseModel.Robust.Create(kernel, noise),
                )
            )
        for key, pose in initial.items():
            values.insert(key, _pose3(gtsam, pose))
    else:
        graph.add(
            gtsam.PriorFactorPose2(
                anchor,
                plane.pose2(gtsam, initial[anchor]),
                gtsam.noiseModel.Isotropic.Sigma(3, 1e-6),
            )
        )
        for edge in edges:
            info = plane.information(information(edge, config.edge_sigma_m))
            noise = gtsam.noiseModel.Gaussian.Information(info)
            graph.add(
                gtsam.BetweenFactorPose2(
                    edge.first,
                    edge.second,
                    plane.pose2(gtsam, edge.first_from_second),
                    gtsam.noiseModel.Robust.Create(kernel, noise),
                )
            )
        for key, pose in initial.items():
            values.insert(key, plane.pose2(gtsam, pose))
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(config.max_iterations)
    params.setRelativeErrorTol(1e-10)
    params.setAbsoluteErrorTol(1e-12)
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, values, params)
    result = optimizer.optimize()
    if plane is None:
        poses = {key: np.asarray(result.atPose3(key).matrix(), dtype=np.float64) for key in initial}
    else:
        poses = {key: plane.pose3(result.atPose2(key)) for key in initial}
    return PoseGraphSolution(
        poses=poses,
        residuals=_residuals(gtsam, edges, poses, config, plane),
        error_before=float(graph.error(values)),
        error_after=float(graph.error(result)),
        iterations=int(optimizer.iterations()),
    )


def residuals(
    edges: list[Edge], poses: dict[int, F64], config: PoseGraphConfig, axis: F64 | None = None
) -> list[EdgeResidual]:
    """Residuals of `edges` against given poses (e.g. outliers left out of the solution)."""
    plane = None if axis is None else _Plane.about(axis)
    return _residuals(backend(), edges, poses, config, plane)


def fuse(estimates: list[tuple[F64, F64]]) -> F64:
    """Weighted mean of rigid transforms, each with a 6x6 information (gtsam's Pose3
    tangent at the estimate): the pose minimising the sum of their whitened errors."""
    if len(estimates) == 1:
        return estimates[0][0]
    gtsam = backend()
    graph = gtsam.NonlinearFactorGraph()
    for transform, info in estimates:
        regular = info + np.eye(6) * 1e-9 * max(float(np.trace(info)), 1.0)
        graph.add(
            gtsam.PriorFactorPose3(
                0, _pose3(gtsam, transform), gtsam.noiseModel.Gaussian.Information(regular)
            )
        )
    values = gtsam.Values()
    values.insert(0, _pose3(gtsam, estimates[0][0]))
    result = gtsam.LevenbergMarquardtOptimizer(
        graph, values, gtsam.LevenbergMarquardtParams()
    ).optimize()
    return np.asarray(result.atPose3(0).matrix(), dtype=np.float64)
