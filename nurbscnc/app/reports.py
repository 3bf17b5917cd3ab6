"""The JSON data of the geometric reports: sharp corners (``corners``) and the PH quintic
fits of the corner regions (``ph``)."""

from __future__ import annotations


def corners_json(result, junctions) -> dict:
    """The sharp corners of every NURBS block (SPEC §5: κ above κ_th = A_max/F²) and the
    tangent junctions between segments."""
    import numpy as np

    return {
        "ok": True,
        "blocks": [
            {
                "line": sc.line,
                "segment": sc.segment_index,
                "feed_mm_s": sc.feed_mm_s,
                "kappa_threshold_per_mm": sc.kappa_threshold_per_mm,
                "corners": [
                    {
                        # JSON has no infinity: a cusp's curvature is null.
                        "kappa_peak_per_mm": (
                            r.kappa_peak_per_mm if np.isfinite(r.kappa_peak_per_mm) else None
                        ),
                        "u_peak": r.u_peak,
                        "point_mm": list(r.point_mm),
                        "u_a": r.u_a,
                        "u_b": r.u_b,
                        "length_mm": r.length_mm,
                    }
                    for r in sc.regions
                ],
            }
            for sc in result
        ],
        "junctions": [
            {
                "segment": j.index,
                "line": j.line,
                "point_mm": list(j.point_mm),
                "angle_deg": j.angle_deg,
            }
            for j in junctions
        ],
    }


def region_name(k: int) -> str:
    """AB, CD, EF, ... as the paper names its regions."""
    letters = "ABCDEFGHIJKLMNOPQRSTUVWXYZ"
    a = (2 * k) % 26
    suffix = "" if k < 13 else str(k // 13)
    return letters[a] + letters[a + 1] + suffix


def ph_json(rows, e_um: float, no_split: bool) -> dict:
    """The PH quintic fits of the corner regions (Table 1 layout) at tolerance ``e_um`` [µm]."""
    regions = []
    for k, (sc, r, unsplit, fit) in enumerate(rows):
        regions.append(
            {
                "region": region_name(k),
                "line": sc.line,
                "u_a": r.u_a,
                "u_b": r.u_b,
                "length_mm": r.length_mm,
                "unsplit": {"rms_um": unsplit.rms_um, "max_um": unsplit.max_um},
                "rms_um": fit.rms_um,
                "max_um": fit.max_um,
                "pieces": [
                    {
                        "line": sc.line,
                        "u_a": piece.u_a,
                        "u_b": piece.u_b,
                        "control_points_mm": [
                            [float(c) for c in pt] for pt in piece.ph.control_points_mm
                        ],
                        "rms_um": piece.rms_um,
                        "max_um": piece.max_um,
                    }
                    for piece in fit.pieces
                ],
            }
        )
    return {"ok": True, "tolerance_um": e_um, "split": not no_split, "regions": regions}
