"""Ray-cast calibration environment: ground, walls, boxes and poles, hit by exact geometry.

Used by the simulator to produce honest LiDAR scans: every range is the exact distance to
the nearest primitive along the beam, plus configurable Gaussian range noise. World frame:
z up, ground at z = 0, turntable pivot at the origin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from syncaudit.simulate import rigid
from syncaudit.simulate.calib_config import LidarSimConfig, SceneConfig

F64 = NDArray[np.float64]
_EPS_M = 1e-6


@dataclass(frozen=True)
class Box:
    """Box standing on or above the ground, rotated about z (walls are thin boxes)."""

    center_m: tuple[float, float, float]
    size_m: tuple[float, float, float]
    yaw_rad: float
    kind: str
    reflectivity: float

    def to_json_dict(self) -> dict[str, Any]:
        """Plain-JSON description."""
        return {
            "type": self.kind,
            "center_m": list(self.center_m),
            "size_m": list(self.size_m),
            "yaw_deg": math.degrees(self.yaw_rad),
        }


@dataclass(frozen=True)
class Pole:
    """Vertical cylinder standing on the ground."""

    center_xy_m: tuple[float, float]
    radius_m: float
    height_m: float
    reflectivity: float

    def to_json_dict(self) -> dict[str, Any]:
        """Plain-JSON description."""
        return {
            "type": "pole",
            "center_xy_m": list(self.center_xy_m),
            "radius_m": self.radius_m,
            "height_m": self.height_m,
        }


@dataclass(frozen=True)
class Hits:
    """Ray-cast result per ray: range (inf = no hit), |cos| of incidence, surface reflectivity."""

    range_m: F64
    cos_incidence: F64
    reflectivity: F64


@dataclass(frozen=True)
class Scene:
    """Ground plane plus boxes and poles."""

    boxes: tuple[Box, ...]
    poles: tuple[Pole, ...]
    ground_reflectivity: float = 0.2

    def to_json_dict(self) -> dict[str, Any]:
        """Plain-JSON description of every primitive."""
        return {
            "ground": {"type": "plane", "z_m": 0.0},
            "objects": [b.to_json_dict() for b in self.boxes]
            + [p.to_json_dict() for p in self.poles],
        }

    def raycast(self, origins_m: F64, directions: F64) -> Hits:
        """Nearest hit along each ray; `origins_m` (N, 3) or (3,), `directions` (N, 3) unit."""
        dirs = np.asarray(directions, dtype=np.float64)
        origins = np.broadcast_to(np.asarray(origins_m, dtype=np.float64), dirs.shape)
        n = dirs.shape[0]
        best = np.full(n, np.inf)
        cos_inc = np.zeros(n)
        refl = np.zeros(n)

        def take(t: F64, cos: F64, reflectivity: float) -> None:
            closer = t < best
            best[closer] = t[closer]
            cos_inc[closer] = cos[closer]
            refl[closer] = reflectivity

        def take_at(idx: NDArray[np.int64], t: F64, cos: F64, reflectivity: float) -> None:
            closer = t < best[idx]
            sel = idx[closer]
            best[sel] = t[closer]
            cos_inc[sel] = cos[closer]
            refl[sel] = reflectivity

        # Ground plane z = 0.
        dz = dirs[:, 2]
        down = dz < -1e-9
        t_ground = np.where(down, -origins[:, 2] / np.where(down, dz, -1.0), np.inf)
        take(np.where(t_ground > _EPS_M, t_ground, np.inf), np.abs(dz), self.ground_reflectivity)
        for box in self.boxes:
            idx = _near_rays(
                origins, dirs, np.asarray(box.center_m), float(np.linalg.norm(box.size_m)) / 2.0
            )
            t_box, cos_box = _ray_box(origins[idx], dirs[idx], box)
            take_at(idx, t_box, cos_box, box.reflectivity)
        for pole in self.poles:
            center = np.array([*pole.center_xy_m, pole.height_m / 2.0])
            idx = _near_rays(origins, dirs, center, math.hypot(pole.radius_m, pole.height_m / 2.0))
            t_pole, cos_pole = _ray_pole(origins[idx], dirs[idx], pole)
            take_at(idx, t_pole, cos_pole, pole.reflectivity)
        return Hits(range_m=best, cos_incidence=cos_inc, reflectivity=refl)


def _near_rays(origins: F64, dirs: F64, center: F64, radius_m: float) -> NDArray[np.int64]:
    """Indices of rays that pass within `radius_m` of `center` ahead of their origin: the
    only ones that can hit a primitive inside that bounding sphere (exact culling)."""
    rel = center - origins
    along = np.einsum("ij,ij->i", rel, dirs)
    miss2 = np.einsum("ij,ij->i", rel, rel) - along * along
    return np.flatnonzero((miss2 <= radius_m * radius_m) & (along > -radius_m))


def _ray_box(origins: F64, dirs: F64, box: Box) -> tuple[F64, F64]:
    """Slab test in the box frame: entry distance (inf = miss) and |cos| of incidence."""
    rot = rigid.yaw_matrix(box.yaw_rad)
    p = (origins - np.asarray(box.center_m)) @ rot  # rows: R^T (o - c)
    d = dirs @ rot
    half = np.asarray(box.size_m) / 2.0
    d_safe = np.where(np.abs(d) < 1e-12, 1e-12, d)
    t1 = (-half - p) / d_safe
    t2 = (half - p) / d_safe
    t_lo = np.minimum(t1, t2)
    t_near = t_lo.max(axis=1)
    t_far = np.maximum(t1, t2).min(axis=1)
    hit = (t_far >= t_near) & (t_near > _EPS_M)
    axis = t_lo.argmax(axis=1)
    cos = np.abs(d[np.arange(d.shape[0]), axis])
    return np.where(hit, t_near, np.inf), cos


def _ray_pole(origins: F64, dirs: F64, pole: Pole) -> tuple[F64, F64]:
    """Side wall and top cap of a vertical cylinder: entry distance and |cos| of incidence."""
    px = origins[:, 0] - pole.center_xy_m[0]
    py = origins[:, 1] - pole.center_xy_m[1]
    dx, dy, dz = dirs[:, 0], dirs[:, 1], dirs[:, 2]
    a = dx * dx + dy * dy
    b = 2.0 * (px * dx + py * dy)
    c = px * px + py * py - pole.radius_m**2
    disc = b * b - 4.0 * a * c
    ok = (a > 1e-12) & (disc >= 0.0)
    # Misses get a placeholder distance of 0 so no inf * 0 arises; they are masked below.
    t_side = np.where(ok, (-b - np.sqrt(np.where(ok, disc, 0.0))) / np.where(ok, 2.0 * a, 1.0), 0.0)
    z_side = origins[:, 2] + t_side * dz
    side_hit = ok & (t_side > _EPS_M) & (z_side >= 0.0) & (z_side <= pole.height_m)
    nx = (px + t_side * dx) / pole.radius_m
    ny = (py + t_side * dy) / pole.radius_m
    cos_side = np.abs(nx * dx + ny * dy)
    vertical = np.abs(dz) > 1e-12
    t_cap = np.where(vertical, (pole.height_m - origins[:, 2]) / np.where(vertical, dz, 1.0), 0.0)
    cx = px + t_cap * dx
    cy = py + t_cap * dy
    cap_hit = vertical & (t_cap > _EPS_M) & (cx * cx + cy * cy <= pole.radius_m**2)
    t_side = np.where(side_hit, t_side, np.inf)
    t_cap = np.where(cap_hit, t_cap, np.inf)
    use_cap = t_cap < t_side
    return np.where(use_cap, t_cap, t_side), np.where(use_cap, np.abs(dz), cos_side)


def build_scene(config: SceneConfig, rng: np.random.Generator) -> Scene:
    """Random but seeded environment around the turntable at the origin."""
    if config.kind == "ground_and_wall":
        yaw = float(rng.uniform(-math.pi, math.pi))
        dist_m = config.clear_radius_m + 2.0
        center = (dist_m * math.cos(yaw), dist_m * math.sin(yaw), 1.5)
        wall = Box(center, (0.3, 80.0, 3.0), yaw, "wall", 0.5)
        return Scene(boxes=(wall,), poles=())
    if config.kind == "corridor":
        yaw = float(rng.uniform(-math.pi, math.pi))
        half_m = config.clear_radius_m + 1.0
        walls = []
        for side in (-1.0, 1.0):
            center = (-side * half_m * math.sin(yaw), side * half_m * math.cos(yaw), 1.5)
            walls.append(Box(center, (80.0, 0.3, 3.0), yaw, "wall", 0.5))
        return Scene(boxes=tuple(walls), poles=())
    if config.kind in ("parking_lot", "parking_lot_open", "parking_lot_facing"):
        return _parking_lot(config, rng)
    size_x, size_y = config.yard_size_m
    yard_yaw = float(rng.uniform(-math.pi, math.pi))
    offset = rng.uniform(-1.0, 1.0, size=2)
    rot2 = rigid.yaw_matrix(yard_yaw)[:2, :2]
    boxes: list[Box] = []
    for local_xy, length, along_y in (
        ((size_x / 2.0, 0.0), size_y, True),
        ((-size_x / 2.0, 0.0), size_y, True),
        ((0.0, size_y / 2.0), size_x, False),
        ((0.0, -size_y / 2.0), size_x, False),
    ):
        height = float(rng.uniform(2.5, 4.0))
        cx, cy = rot2 @ np.asarray(local_xy) + offset
        size = (0.3, length + 0.3, height) if along_y else (length + 0.3, 0.3, height)
        boxes.append(Box((float(cx), float(cy), height / 2.0), size, yard_yaw, "wall", 0.5))
    max_r = min(size_x, size_y) / 2.0 - 1.0
    # Objects are spread over the circle (one per equal sector, jittered inside it), as a
    # calibration bay places its targets: every view of the turntable sees some of them.
    n_objects = config.n_boxes + config.n_poles
    kinds = ["box"] * config.n_boxes + ["pole"] * config.n_poles
    order = rng.permutation(n_objects)
    sector = 2.0 * math.pi / max(n_objects, 1)
    start = float(rng.uniform(-math.pi, math.pi))
    poles: list[Pole] = []
    for slot, which in enumerate(order):
        ang = start + (slot + float(rng.uniform(0.1, 0.9))) * sector
        r = float(rng.uniform(config.clear_radius_m, max_r))
        x, y = r * math.cos(ang), r * math.sin(ang)
        if kinds[int(which)] == "box":
            sx, sy = (float(v) for v in rng.uniform(0.4, 2.0, size=2))
            sz = float(rng.uniform(0.5, 2.5))
            yaw = float(rng.uniform(-math.pi, math.pi))
            boxes.append(Box((x, y, sz / 2.0), (sx, sy, sz), yaw, "box", 0.7))
        else:
            radius = float(rng.uniform(0.05, 0.2))
            poles.append(Pole((x, y), radius, float(rng.uniform(1.5, 5.0)), 0.9))
    return Scene(boxes=tuple(boxes), poles=tuple(poles))


_CAR_SLOT_M = 2.6
_CAR_LENGTH_M = 4.6
_CAR_OCCUPANCY = 0.7
_FACING_YAW_DEG = 30.0
"""`parking_lot_facing`: the aisle 30 deg left of the vehicle's start heading, so a
rear-facing LiDAR sees the cars (obliquely, down the aisle) at the first few stops of a
left-turning drive and the front one faces them from then on."""


def _parking_lot(config: SceneConfig, rng: np.random.Generator) -> Scene:
    """Rows of nose-in parked cars (70 % of slots taken) either side of the aisle the
    vehicle drives in, back-to-back rows behind them, lamp posts between those, a
    building along one long side and nothing else (no enclosing walls: the far field is
    open tarmac). `parking_lot_open` keeps only the cars on one side (y > 0) of the aisle;
    `parking_lot_facing` too, and is not rotated at random (its aisle 30 deg left of the
    world x within a few degrees, the cars on its +y side).

    The lot is rotated and shifted at random as a whole; the aisle runs along its x.
    """
    size_x, size_y = config.yard_size_m
    facing = config.kind == "parking_lot_facing"
    lot_yaw = (
        math.radians(_FACING_YAW_DEG) + float(rng.normal(0.0, 0.05))
        if facing
        else float(rng.uniform(-math.pi, math.pi))
    )
    offset = rng.uniform(-0.5, 0.5, size=2)
    rot2 = rigid.yaw_matrix(lot_yaw)[:2, :2]

    def place(x: float, y: float) -> tuple[float, float]:
        cx, cy = rot2 @ np.array([x, y]) + offset
        return float(cx), float(cy)

    boxes: list[Box] = []
    poles: list[Pole] = []
    first_row_m = config.clear_radius_m + 2.5 + _CAR_LENGTH_M / 2.0
    sides = (1.0,) if config.kind in ("parking_lot_open", "parking_lot_facing") else (1.0, -1.0)
    n_slots = int((size_x - 4.0) // _CAR_SLOT_M)
    x0 = -n_slots * _CAR_SLOT_M / 2.0
    for side in sides:
        for row_y in (first_row_m, first_row_m + _CAR_LENGTH_M + 0.3):
            if row_y + _CAR_LENGTH_M / 2.0 > size_y / 2.0:
                continue
            for slot in range(n_slots):
                if rng.uniform() > _CAR_OCCUPANCY:
                    continue
                x = x0 + (slot + 0.5) * _CAR_SLOT_M + float(rng.normal(0.0, 0.15))
                width = float(rng.uniform(1.7, 2.0))
                length = float(rng.uniform(4.0, 5.0))
                height = float(rng.uniform(1.4, 2.1))
                cx, cy = place(x, side * (row_y + float(rng.normal(0.0, 0.2))))
                yaw = lot_yaw + math.pi / 2.0 + float(rng.normal(0.0, 0.05))
                boxes.append(
                    Box((cx, cy, height / 2.0 + 0.15), (length, width, height), yaw, "car", 0.6)
                )
        lamp_y = side * (first_row_m + (_CAR_LENGTH_M + 0.3) / 2.0)
        for slot in range(2, n_slots, 5):
            cx, cy = place(x0 + slot * _CAR_SLOT_M, lamp_y)
            poles.append(Pole((cx, cy), 0.12, float(rng.uniform(5.0, 7.0)), 0.9))
    cx, cy = place(0.0, size_y / 2.0 + 1.0)
    boxes.append(Box((cx, cy, 4.0), (size_x, 2.0, 8.0), lot_yaw, "wall", 0.5))
    return Scene(boxes=tuple(boxes), poles=tuple(poles))


@dataclass(frozen=True)
class BeamPattern:
    """Unit beam directions of one LiDAR in its own frame, with ring and column indices."""

    directions: F64
    ring: NDArray[np.uint16]
    column: NDArray[np.int64]
    n_columns: int


def beam_pattern(lidar: LidarSimConfig) -> BeamPattern:
    """Evenly spaced elevations and azimuths over the LiDAR's FOV (x forward, z up)."""
    lo, hi = (math.radians(v) for v in lidar.vertical_fov_deg)
    elevations = np.linspace(lo, hi, lidar.beams)
    n_columns = max(1, round(lidar.horizontal_fov_deg / lidar.horizontal_resolution_deg))
    hfov = math.radians(lidar.horizontal_fov_deg)
    azimuths = -hfov / 2.0 + (np.arange(n_columns) + 0.5) * hfov / n_columns
    az, el = np.meshgrid(azimuths, elevations, indexing="xy")  # (beams, columns)
    dirs = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1)
    ring, column = np.meshgrid(
        np.arange(lidar.beams, dtype=np.uint16), np.arange(n_columns), indexing="ij"
    )
    # Column-major order, as a spinning LiDAR fires all its beams per column.
    return BeamPattern(
        directions=dirs.transpose(1, 0, 2).reshape(-1, 3),
        ring=ring.T.reshape(-1),
        column=column.T.reshape(-1),
        n_columns=n_columns,
    )


@dataclass(frozen=True)
class SimulatedScan:
    """Raw points of one scan in the LiDAR frame (as a non-deskewing driver publishes them)."""

    points_m: NDArray[np.float32]
    intensity: NDArray[np.float32]
    ring: NDArray[np.uint16]
    column: NDArray[np.int64]


def simulate_scan(
    scene: Scene,
    lidar: LidarSimConfig,
    pattern: BeamPattern,
    world_from_lidar: F64,
    rng: np.random.Generator,
) -> SimulatedScan:
    """Cast every beam; `world_from_lidar` is (4, 4) for a static scan or (C, 4, 4) per column.

    Per-column poses model a scan taken while the vehicle turns: each column is fired from
    where the LiDAR was at that instant, but reported in the sensor frame of that instant,
    so the published cloud is motion-distorted exactly as a real one without deskewing.
    """
    if world_from_lidar.ndim == 2:
        rot = world_from_lidar[:3, :3]
        dirs_w = pattern.directions @ rot.T
        origins = np.broadcast_to(world_from_lidar[:3, 3], dirs_w.shape)
    else:
        per_ray = world_from_lidar[pattern.column]
        dirs_w = np.einsum("nij,nj->ni", per_ray[:, :3, :3], pattern.directions)
        origins = per_ray[:, :3, 3]
    hits = scene.raycast(origins, dirs_w)
    noisy = hits.range_m + rng.normal(0.0, lidar.range_noise_m, size=hits.range_m.shape)
    keep = (
        np.isfinite(hits.range_m)
        & (hits.range_m >= lidar.min_range_m)
        & (hits.range_m <= lidar.max_range_m)
    )
    ranges = noisy[keep]
    points = pattern.directions[keep] * ranges[:, None]
    intensity = 255.0 * hits.reflectivity[keep] * (0.3 + 0.7 * hits.cos_incidence[keep])
    intensity /= 1.0 + (ranges / 60.0) ** 2
    return SimulatedScan(
        points_m=points.astype(np.float32),
        intensity=np.clip(intensity, 0.0, 255.0).astype(np.float32),
        ring=pattern.ring[keep],
        column=pattern.column[keep],
    )
