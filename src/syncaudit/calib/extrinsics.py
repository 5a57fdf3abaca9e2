"""The vehicle's recorded LiDAR extrinsics, from `/tf_static` or from a YAML/JSON file.

File format (YAML or JSON)::

    base_frame: base_link
    extrinsics:
      lidar_front: {translation_m: [2.2, 0.05, 1.95], rpy_deg: [0.4, 4.0, 1.5]}
      lidar_rear: {translation_m: [-0.6, -0.08, 1.85], quaternion_xyzw: [0, 0, 1, 0]}
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from pydantic import Field, model_validator

from syncaudit.calib import se3
from syncaudit.calib.io import StaticTransform
from syncaudit.calib.settings import ConfigModel, load_config
from syncaudit.errors import NoDataError

F64 = NDArray[np.float64]


class ExtrinsicEntry(ConfigModel):
    """One `base_from_lidar` transform: translation plus roll/pitch/yaw or a quaternion."""

    translation_m: tuple[float, float, float]
    rpy_deg: tuple[float, float, float] | None = None
    quaternion_xyzw: tuple[float, float, float, float] | None = None

    @model_validator(mode="after")
    def _check(self) -> ExtrinsicEntry:
        if (self.rpy_deg is None) == (self.quaternion_xyzw is None):
            raise ValueError("give exactly one of rpy_deg or quaternion_xyzw")
        if self.quaternion_xyzw is not None and not math.isclose(
            float(np.linalg.norm(self.quaternion_xyzw)), 1.0, abs_tol=1e-3
        ):
            raise ValueError("quaternion_xyzw must be a unit quaternion")
        return self

    def matrix(self) -> F64:
        """The 4x4 `base_from_lidar`."""
        if self.quaternion_xyzw is not None:
            rot = se3.quaternion_to_matrix(*self.quaternion_xyzw)
        else:
            assert self.rpy_deg is not None
            rot = se3.rpy_to_matrix(*(math.radians(v) for v in self.rpy_deg))
        return se3.make_transform(rot, self.translation_m)


class ExtrinsicsFile(ConfigModel):
    """A file of recorded extrinsics keyed by LiDAR frame id."""

    base_frame: str = Field(default="base_link", min_length=1)
    extrinsics: dict[str, ExtrinsicEntry] = Field(min_length=1)


@dataclass(frozen=True)
class RecordedExtrinsics:
    """`base_from_frame` for every LiDAR frame, all relative to one common base frame."""

    source: str
    base_frame: str
    base_from_frame: dict[str, F64]

    def relative(self, reference: str, other: str) -> F64:
        """`reference_from_other` implied by the recorded extrinsics."""
        return se3.invert(self.base_from_frame[reference]) @ self.base_from_frame[other]


def from_static_transforms(
    edges: list[StaticTransform], frames: Iterable[str], source: str
) -> RecordedExtrinsics:
    """Resolve each frame up the static tree to a common root; NoDataError if impossible."""
    parent_of = {edge.child: edge for edge in edges}
    chains: dict[str, tuple[str, F64]] = {}
    for frame in frames:
        transform = np.eye(4)
        node = frame
        seen = {node}
        while node in parent_of:
            edge = parent_of[node]
            transform = edge.parent_from_child @ transform
            node = edge.parent
            if node in seen:
                raise NoDataError(f"{source}: transform loop through frame {node}")
            seen.add(node)
        if node == frame:
            raise NoDataError(f"{source}: no transform for LiDAR frame {frame}")
        chains[frame] = (node, transform)
    roots = {root for root, _ in chains.values()}
    if len(roots) != 1:
        raise NoDataError(
            f"{source}: LiDAR frames hang off different roots ({', '.join(sorted(roots))})"
        )
    return RecordedExtrinsics(
        source=source,
        base_frame=roots.pop(),
        base_from_frame={frame: chain[1] for frame, chain in chains.items()},
    )


def from_file(path: Path, frames: Iterable[str]) -> RecordedExtrinsics:
    """Read an extrinsics file; NoDataError when a LiDAR frame is missing from it."""
    parsed: ExtrinsicsFile = load_config(path, ExtrinsicsFile)
    out = {}
    for frame in frames:
        entry = parsed.extrinsics.get(frame)
        if entry is None:
            raise NoDataError(f"{path}: no extrinsic for LiDAR frame {frame}")
        out[frame] = entry.matrix()
    return RecordedExtrinsics(source=str(path), base_frame=parsed.base_frame, base_from_frame=out)
