"""Per-LiDAR summary after the pose graphs: stops used, why the others were not, pair outputs."""

from __future__ import annotations

from syncaudit.calib.graph import posegraph
from syncaudit.calib.graph.links import components
from syncaudit.calib.result import AlignmentOut, PairOut, PoseGraphOut
from syncaudit.calib.settings import CalibConfig
from syncaudit.calib.state import LidarState


def _causes(lidar: LidarState) -> str:
    """Why a LiDAR's stops did not join: unknown vehicle motion and rejected pairs, counted
    by kind, each with its first example."""
    parts = []
    unknown = [k for k, angle in lidar.angles.items() if angle is None]
    if unknown:
        first = lidar.dropped.get(min(unknown), "motion unknown")
        parts.append(
            f"the vehicle's motion to {len(unknown)} stop(s) could not be found, "
            f"first at stop {min(unknown)}: {first}"
        )
    rejected = [r.reason for r in lidar.results.values() if not r.accepted and r.reason]
    if rejected:
        kinds: dict[str, int] = {}
        for reason in rejected:
            kind = reason.split(":")[0].split(" ")[0]
            kinds[kind] = kinds.get(kind, 0) + 1
        counted = ", ".join(f"{n} {kind}" for kind, n in sorted(kinds.items()))
        parts.append(
            f"{len(rejected)} of {len(lidar.results)} pair alignments rejected ({counted}), "
            f"e.g. {rejected[0]}"
        )
    elif not lidar.results:
        parts.append("no pairs of stops whose views should overlap")
    return "; ".join(parts) or "no accepted alignments"


def summarize_lidar(lidar: LidarState, main: int, config: CalibConfig) -> None:
    """Used stops, reasons for the others, pose-graph totals and per-pair output."""
    sel = config.selection
    used: set[int] = set()
    residuals: dict[tuple[int, int], posegraph.EdgeResidual] = {}
    for solution in lidar.graphs.values():
        used |= set(solution.poses)
        residuals.update({(r.first, r.second): r for r in solution.residuals})
    lidar.used = used
    for group in components(lidar):
        for k in group - used:
            if len(group) < sel.min_stops:
                lidar.dropped.setdefault(
                    k,
                    f"its group of {len(group)} connected stop(s) is too small "
                    f"(need {sel.min_stops})",
                )
            else:
                lidar.dropped.setdefault(k, "its group shares no stop with the other LiDARs' maps")
    if lidar.graphs:
        sols = list(lidar.graphs.values())
        lidar.graph = PoseGraphOut(
            graphs=len(sols),
            nodes=sum(len(s.poses) for s in sols),
            edges=sum(len(s.residuals) for s in sols),
            outlier_edges=sum(1 for s in sols for r in s.residuals if r.outlier),
            error_before=sum(s.error_before for s in sols),
            error_after=sum(s.error_after for s in sols),
            iterations=max(s.iterations for s in sols),
        )
    else:
        largest = max((len(g) for g in components(lidar)), default=0)
        lidar.reason = (
            f"{lidar.topic}: at most {largest} of {len(lidar.stop_scan)} stops could be "
            f"aligned together ({_causes(lidar)}); need {sel.min_stops}"
        )
        lidar.dropped.setdefault(main, "too few stops aligned to it")
    for a, b, sep, pred in lidar.candidates:
        graph_res = residuals.get((a, b))
        lidar.pairs.append(
            PairOut(
                first_stop=a,
                second_stop=b,
                separation_deg=sep,
                predicted_overlap=pred,
                alignment=AlignmentOut.of(lidar.results[(a, b)]),
                graph_residual_rotation_deg=None if graph_res is None else graph_res.rotation_deg,
                graph_residual_translation_cm=(
                    None if graph_res is None else graph_res.translation_cm
                ),
                graph_outlier=None if graph_res is None else graph_res.outlier,
            )
        )
