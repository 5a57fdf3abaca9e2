"""One factor graph over every LiDAR: the vehicle's stop poses and the extrinsics together.

Unknowns are the reference LiDAR's pose at every stop (`X_k`, in its frame at the anchor
stop) and each other LiDAR's extrinsic (`E_j` = reference_from_lidar_j). A cross-scan
alignment of LiDAR j between stops a and b measures `E_j^-1 X_a^-1 X_b E_j`, so a stop seen
by one LiDAR only still places the vehicle, and through it constrains every other LiDAR's
extrinsic (the hand-eye constraint AX = XB). Other factors: a cross-LiDAR alignment (or a
map-to-map one) measures `E_i^-1 X_a^-1 X_b E_j`; odometry measures `X_a^-1 X_b`; a ground
plane seen by two LiDARs ties their tilt and height; a planar-motion prior keeps the
vehicle on the floor. Every alignment factor carries its point-to-plane Hessian as its
information under a robust kernel (`PoseGraphConfig`).

The Jacobians are numerical (central differences on gtsam's retraction): the graphs hold
tens of factors, so this costs well under a second and needs no hand-derived derivatives.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from syncaudit.calib import se3
from syncaudit.calib.graph.posegraph import backend
from syncaudit.calib.settings import PoseGraphConfig

F64 = NDArray[np.float64]
_WEAK_PRIOR_SIGMA = 100.0
_STEP = 1e-6
"""Central-difference step on the tangent space (rad / m)."""


@dataclass(frozen=True)
class Link:
    """A measured `lidar_a at stop_a <- lidar_b at stop_b` pose, with its 6x6 information
    ([rotation, translation] tangent at the second pose, already scaled)."""

    lidar_a: int
    stop_a: int
    lidar_b: int
    stop_b: int
    a_from_b: F64
    information: F64
    kind: str
    """"scan" (a cross-scan alignment), "map" (map to map), "odometry"."""


@dataclass(frozen=True)
class Ground:
    """The ground plane in one LiDAR's frame: unit normal (up) and offset (n.p + d = 0)."""

    lidar: int
    normal: F64
    offset_m: float
    sigma_deg: float
    sigma_m: float
    spread_deg: float = 0.0
    """Median angle of the per-stop normals from `normal` (how flat the ground is)."""


@dataclass(frozen=True)
class LinkResidual:
    """How far the solution is from one link, whitened."""

    link: Link
    rotation_deg: float
    translation_cm: float
    sigmas: float


@dataclass(frozen=True)
class JointSolution:
    """The solved graph: stop poses, extrinsics, their marginal covariances, residuals."""

    poses: dict[int, F64]
    extrinsics: dict[int, F64]
    covariances: dict[int, F64]
    """6x6 marginal covariance of each extrinsic ([rotation rad, translation m], body)."""
    residuals: list[LinkResidual]
    error_before: float
    error_after: float
    iterations: int


def _x(gtsam: Any, stop: int) -> int:
    return int(gtsam.symbol("x", stop))


def _e(gtsam: Any, lidar: int) -> int:
    return int(gtsam.symbol("e", lidar))


def _pose3(gtsam: Any, transform: F64) -> Any:
    return gtsam.Pose3(np.ascontiguousarray(transform, dtype=np.float64))


def _regular(info: F64) -> F64:
    return np.asarray(info + np.eye(6) * 1e-9 * max(float(np.trace(info)), 1.0))


class _Predict:
    """The pose a link predicts from the current values, by key role."""

    def __init__(self, gtsam: Any, link: Link) -> None:
        self.gtsam = gtsam
        self.link = link
        keys: list[int] = []
        if link.stop_a != link.stop_b or link.kind == "odometry":
            keys += [_x(gtsam, link.stop_a), _x(gtsam, link.stop_b)]
        if link.lidar_a:
            keys.append(_e(gtsam, link.lidar_a))
        if link.lidar_b and _e(gtsam, link.lidar_b) not in keys:
            keys.append(_e(gtsam, link.lidar_b))
        self.keys = keys

    def pose(self, get: dict[int, Any]) -> Any:
        g, link = self.gtsam, self.link
        ident = g.Pose3()
        ea = get[_e(g, link.lidar_a)] if link.lidar_a else ident
        eb = get[_e(g, link.lidar_b)] if link.lidar_b else ident
        if link.stop_a != link.stop_b or link.kind == "odometry":
            motion = get[_x(g, link.stop_a)].between(get[_x(g, link.stop_b)])
        else:
            motion = ident
        return ea.inverse().compose(motion).compose(eb)


def _link_factor(gtsam: Any, link: Link, kernel: Any) -> Any:
    predict = _Predict(gtsam, link)
    measured = _pose3(gtsam, link.a_from_b)

    def error(get: dict[int, Any]) -> F64:
        return np.asarray(gtsam.Pose3.Logmap(measured.between(predict.pose(get))))

    noise = gtsam.noiseModel.Gaussian.Information(_regular(link.information))
    return _custom(gtsam, predict.keys, error, gtsam.noiseModel.Robust.Create(kernel, noise), 6)


def _custom(gtsam: Any, keys: list[int], error: Any, noise: Any, dim: int) -> Any:
    """A gtsam CustomFactor of Pose3 variables with central-difference Jacobians."""

    def evaluate(_this: Any, values: Any, jacobians: Any) -> F64:
        get = {k: values.atPose3(k) for k in keys}
        value = np.asarray(error(get), dtype=np.float64)
        if jacobians is not None:
            for i, key in enumerate(keys):
                jac = np.zeros((dim, 6))
                base = get[key]
                for d in range(6):
                    delta = np.zeros(6)
                    delta[d] = _STEP
                    get[key] = base.retract(delta)
                    plus = np.asarray(error(get))
                    get[key] = base.retract(-delta)
                    minus = np.asarray(error(get))
                    jac[:, d] = (plus - minus) / (2.0 * _STEP)
                get[key] = base
                jacobians[i] = jac
        return value

    return gtsam.CustomFactor(noise, gtsam.KeyVector(keys), evaluate)


def _ground_factor(gtsam: Any, ref: Ground, other: Ground) -> Any:
    """The other LiDAR's ground, moved by its extrinsic, lies on the reference's: tilt
    (two angles) and height (along the normal)."""
    key = _e(gtsam, other.lidar)
    n0 = ref.normal / np.linalg.norm(ref.normal)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n0[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = np.cross(n0, helper)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n0, t1)

    def error(get: dict[int, Any]) -> F64:
        ext = np.asarray(get[key].matrix())
        moved = ext[:3, :3] @ other.normal
        offset = other.offset_m - float(moved @ ext[:3, 3])
        return np.array([moved @ t1, moved @ t2, offset - ref.offset_m])

    sigma_rad = math.radians(math.hypot(ref.sigma_deg, other.sigma_deg))
    sigmas = np.array([sigma_rad, sigma_rad, math.hypot(ref.sigma_m, other.sigma_m)])
    return _custom(gtsam, [key], error, gtsam.noiseModel.Diagonal.Sigmas(sigmas), 3)


def _planar_factor(gtsam: Any, stop: int, up: F64, sigma_deg: float, sigma_m: float) -> Any:
    """The vehicle stays on the floor: no tilt about, nor shift along, the reference's up."""
    key = _x(gtsam, stop)
    u = up / np.linalg.norm(up)
    helper = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = np.cross(u, helper)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(u, t1)

    def error(get: dict[int, Any]) -> F64:
        pose = np.asarray(get[key].matrix())
        tilt = pose[:3, :3] @ u
        return np.array([tilt @ t1, tilt @ t2, pose[:3, 3] @ u])

    sigmas = np.array([math.radians(sigma_deg), math.radians(sigma_deg), sigma_m])
    return _custom(gtsam, [key], error, gtsam.noiseModel.Diagonal.Sigmas(sigmas), 3)


@dataclass(frozen=True)
class Problem:
    """Everything the joint graph is built from."""

    anchor: int
    initial_poses: dict[int, F64]
    initial_extrinsics: dict[int, F64]
    links: list[Link]
    grounds: list[Ground]
    up: F64 | None
    """The reference LiDAR's up (turn axis) for the planar-motion prior; None: free motion."""
    planar_sigma_deg: float = 0.05
    planar_sigma_m: float = 0.005


def solve(problem: Problem, config: PoseGraphConfig) -> JointSolution:
    """Levenberg-Marquardt over the joint graph, then each extrinsic's marginal covariance."""
    gtsam = backend()
    kernel = (
        gtsam.noiseModel.mEstimator.Cauchy.Create(config.kernel_width)
        if config.kernel == "cauchy"
        else gtsam.noiseModel.mEstimator.Huber.Create(config.kernel_width)
    )
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    graph.add(
        gtsam.PriorFactorPose3(
            _x(gtsam, problem.anchor),
            _pose3(gtsam, problem.initial_poses[problem.anchor]),
            gtsam.noiseModel.Isotropic.Sigma(6, 1e-6),
        )
    )
    for stop, pose in problem.initial_poses.items():
        values.insert(_x(gtsam, stop), _pose3(gtsam, pose))
        if problem.up is not None and stop != problem.anchor:
            graph.add(
                _planar_factor(
                    gtsam, stop, problem.up, problem.planar_sigma_deg, problem.planar_sigma_m
                )
            )
    for lidar, ext in problem.initial_extrinsics.items():
        values.insert(_e(gtsam, lidar), _pose3(gtsam, ext))
    # A very weak prior on every variable keeps the system solvable where the data leave
    # a direction free (its marginal then shows a 1-sigma of 100 rad / 100 m).
    weak = gtsam.noiseModel.Isotropic.Sigma(6, _WEAK_PRIOR_SIGMA)
    for stop, pose in problem.initial_poses.items():
        if stop != problem.anchor:
            graph.add(gtsam.PriorFactorPose3(_x(gtsam, stop), _pose3(gtsam, pose), weak))
    for lidar, ext in problem.initial_extrinsics.items():
        graph.add(gtsam.PriorFactorPose3(_e(gtsam, lidar), _pose3(gtsam, ext), weak))
    for link in problem.links:
        graph.add(_link_factor(gtsam, link, kernel))
    ref_ground = next((g for g in problem.grounds if g.lidar == 0), None)
    if ref_ground is not None:
        for ground in problem.grounds:
            if ground.lidar in problem.initial_extrinsics:
                graph.add(_ground_factor(gtsam, ref_ground, ground))
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(config.max_iterations)
    params.setRelativeErrorTol(1e-10)
    params.setAbsoluteErrorTol(1e-12)
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, values, params)
    result = optimizer.optimize()
    poses = {
        k: np.asarray(result.atPose3(_x(gtsam, k)).matrix(), dtype=np.float64)
        for k in problem.initial_poses
    }
    exts = {
        j: np.asarray(result.atPose3(_e(gtsam, j)).matrix(), dtype=np.float64)
        for j in problem.initial_extrinsics
    }
    covariances = {j: _marginal(gtsam, graph, result, _e(gtsam, j)) for j in exts}
    return JointSolution(
        poses=poses,
        extrinsics=exts,
        covariances=covariances,
        residuals=[_residual(gtsam, link, result) for link in problem.links],
        error_before=float(graph.error(values)),
        error_after=float(graph.error(result)),
        iterations=int(optimizer.iterations()),
    )


def _marginal(gtsam: Any, graph: Any, result: Any, key: int) -> F64:
    """Marginal covariance of one variable from the graph linearised at the solution: the
    Schur complement of the information onto its block, regularised so a direction the
    graph leaves free gets a huge variance instead of making the system singular."""
    ordering = gtsam.Ordering()
    stored = result.keys()  # a gtsam KeyVector, not a dict
    others = [k for k in stored if k != key]
    for k in others:
        ordering.push_back(k)
    ordering.push_back(key)
    jac, _rhs = graph.linearize(result).jacobian(ordering)
    info = np.asarray(jac.T @ jac, dtype=np.float64)
    n = info.shape[0] - 6
    schur = (
        info[n:, n:] - info[n:, :n] @ np.linalg.pinv(info[:n, :n], hermitian=True) @ info[:n, n:]
    )
    schur = (schur + schur.T) / 2.0
    eps = 1e-12 * max(float(np.trace(schur)), 1.0)
    return np.asarray(np.linalg.inv(schur + np.eye(6) * eps), dtype=np.float64)


def _residual(gtsam: Any, link: Link, result: Any) -> LinkResidual:
    predict = _Predict(gtsam, link)
    pose = predict.pose({k: result.atPose3(k) for k in predict.keys})
    predicted = np.asarray(pose.matrix(), dtype=np.float64)
    rot_deg, trans_m = se3.transform_difference(link.a_from_b, predicted)
    xi = np.asarray(gtsam.Pose3.Logmap(_pose3(gtsam, link.a_from_b).between(pose)))
    whitened = math.sqrt(max(float(xi @ link.information @ xi), 0.0))
    return LinkResidual(link, rot_deg, trans_m * 100.0, whitened)


def free_directions(
    covariance: F64, max_rotation_deg: float, max_translation_cm: float
) -> list[tuple[str, tuple[float, float, float], float]]:
    """Directions of an extrinsic the graph leaves looser than the validation limits:
    ("rotation" | "translation", unit axis in the LiDAR frame, 1-sigma in deg | cm).

    Rotation and translation blocks are judged apart (their units differ), each by the
    eigenvectors of its marginal covariance."""
    out: list[tuple[str, tuple[float, float, float], float]] = []
    for kind, block, scale, limit in (
        ("rotation", covariance[:3, :3], math.degrees(1.0), max_rotation_deg),
        ("translation", covariance[3:, 3:], 100.0, max_translation_cm),
    ):
        values, vectors = np.linalg.eigh(block)
        for value, vector in zip(values, vectors.T, strict=True):
            sigma = math.sqrt(max(float(value), 0.0)) * scale
            if sigma > limit:
                v = vector if vector[int(np.argmax(np.abs(vector)))] >= 0 else -vector
                out.append((kind, (float(v[0]), float(v[1]), float(v[2])), sigma))
    return out
