"""Hand-built GICP alignments for the calibration's stage tests (no registration)."""

from __future__ import annotations

import numpy as np

from syncaudit.calib.alignment.registration import Alignment, Conditioning, Fit


def hand_alignment(
    target_from_source: np.ndarray,
    *,
    translation_hessian: tuple[float, float, float] = (0.5, 0.5, 0.5),
    translation_information: float = 0.3,
    accepted: bool = True,
) -> Alignment:
    """An alignment whose Hessian's translation block is diagonal (source frame)."""
    hessian = np.eye(6)
    hessian[3:, 3:] = np.diag(translation_hessian)
    cond = Conditioning(translation_information, 0.2, (1.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    fit = Fit(0.6, 0.02, cond, 5000, hessian)
    return Alignment(target_from_source, True, 10, fit, fit, accepted, None if accepted else "x")
