"""Comparison metrics of docs/method.md#7-comparison-metrics and the surface sampling they need (pure numpy/scipy on arrays).

For one comparison of a side ``a`` (EDEM/DEM) against a reference ``b`` (FE or a closed form) at
the same load: signed relative errors (a - b) / |b| of the regularised peak pressure
(:mod:`edem.pressure_metrics`, the judged pressure), the raw peak (reported only), the mean
pressure and the contact area, the bone displacement's |u_a - u_b| / |u_b| signed by whether a
moves more or less than b, and the L2 relative error
of the pressure field on common points: b's pressure is sampled at a's springs (centroids; far
ends when b is another surface such as an FE slab's contact face) by projecting each point onto
b's triangulated surface (:func:`sample_onto` for nodal fields,
exact for fields linear on the surface; :func:`sample_cells_onto` for piecewise-constant ones).
:func:`compare_result_dirs` applies all of it to two result directories (docs/result-format.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from geometries.errors import InputError
from edem.pressure_metrics import PRESSURE_ON_MOBILE, surface_regularised_peak_mpa
from edem.resultdir import read_result_dir
from geometries.triangle_kernels import closest_points_on_triangles


#: docs/method.md#7-comparison-metrics metric names (each a relative error, 0 = identical; signed:
#: negative when a is below b, except the L2 error, a norm) in the order they are printed.
COMPARISON_METRICS = (
    "regularised_peak_pressure_rel_error",
    "peak_pressure_rel_error",
    "mean_pressure_rel_error",
    "contact_area_rel_error",
    "displacement_rel_error",
    "pressure_l2_rel_error",
)


# ---------------------------------------------------------------------------------------------
# Scalar and field errors


def relative_error(value: float | np.ndarray, reference: float | np.ndarray) -> float:
    """|value - reference| / |reference| (Euclidean norms for vectors), docs/method.md#7-comparison-metrics.

    A zero reference gives 0 when the value is zero too and +inf otherwise (never NaN).
    """
    value = np.asarray(value, dtype=np.float64)
    reference = np.asarray(reference, dtype=np.float64)
    diff = float(np.linalg.norm((value - reference).ravel()))
    ref = float(np.linalg.norm(reference.ravel()))
    if ref == 0.0:
        return 0.0 if diff == 0.0 else math.inf
    return diff / ref


def signed_relative_error(value: float, reference: float) -> float:
    """(value - reference) / |reference|: negative when the value is below the reference
    (docs/method.md#7-comparison-metrics). A zero reference gives 0 when the value is zero too
    and +-inf otherwise (never NaN)."""
    diff = float(value) - float(reference)
    if float(reference) == 0.0:
        return 0.0 if diff == 0.0 else math.copysign(math.inf, diff)
    return diff / abs(float(reference))


def peak_pressure_error(peak_mpa: float, reference_peak_mpa: float) -> float:
    """Signed relative error of a peak contact pressure, raw or regularised (docs/method.md#7-comparison-metrics)."""
    return signed_relative_error(peak_mpa, reference_peak_mpa)


def mean_pressure_error(mean_mpa: float, reference_mean_mpa: float) -> float:
    """Signed relative error of the mean contact pressure (contact force over contact area, docs/method.md#7-comparison-metrics)."""
    return signed_relative_error(mean_mpa, reference_mean_mpa)


def contact_area_error(area_mm2: float, reference_area_mm2: float) -> float:
    """Signed relative error of the contact area (docs/method.md#7-comparison-metrics)."""
    return signed_relative_error(area_mm2, reference_area_mm2)


def displacement_error(displacement_mm: np.ndarray, reference_displacement_mm: np.ndarray) -> float:
    """|u - u_ref| / |u_ref| of the bone displacement vectors, negative when |u| < |u_ref| (the
    bone moves less than in the reference; docs/method.md#7-comparison-metrics)."""
    magnitude = relative_error(displacement_mm, reference_displacement_mm)
    shorter = np.linalg.norm(displacement_mm) < np.linalg.norm(reference_displacement_mm)
    return -magnitude if shorter else magnitude


def unloading_branch(load_n: np.ndarray) -> np.ndarray:
    """(T,) bool: the time points whose load magnitude ``load_n`` (T,) N is below the largest one
    before them (by more than 1e-9 of it: round-off of a held load is not unloading)."""
    load = np.abs(np.asarray(load_n, dtype=np.float64))
    before = np.concatenate([[-np.inf], np.maximum.accumulate(load)[:-1]])
    return load < before * (1.0 - 1e-9)


#: per-time scalar errors and the (a, b) values they compare: on the unloading branch each is
#: taken against b's largest magnitude up to that instant (:func:`against_cycle_peak`)
_CYCLE_PEAK_ERRORS = (
    ("regularised_peak_pressure_rel_error", "regularised_peak_pressure_a_mpa", "regularised_peak_pressure_b_mpa"),
    ("peak_pressure_rel_error", "peak_pressure_a_mpa", "peak_pressure_b_mpa"),
    ("mean_pressure_rel_error", "mean_pressure_a_mpa", "mean_pressure_b_mpa"),
    ("contact_area_rel_error", "contact_area_a_mm2", "contact_area_b_mm2"),
)


def against_cycle_peak(per_time: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The per-time comparison with its relative errors on the unloading branch taken against the
    reference's peak in the cycle (docs/method.md#7-comparison-metrics).

    Unloaded towards zero, the reference's response goes to zero with the load, and (a - b) / |b|
    grows without bound while both sides agree to a fraction of what the cycle loaded them with.
    At a time point on the unloading branch (:func:`unloading_branch` of the loads) each scalar
    error is (a - b) divided by the largest |b| up to that instant, the displacement error is
    |u_a - u_b| / max |u_b| (its sign as :func:`displacement_error`'s) and the pressure field's is
    its L2 misfit over the largest L2 norm of b's field so far; those entries say so
    (``relative_to``: "cycle peak"). Unloaded time points before the first load are taken against
    b's largest magnitude over the whole history (``relative_to``: "history peak"): their reference
    is zero and their relative error otherwise 0 or inf. Loading branches are unchanged. Returns
    new dicts.
    """
    if not per_time:
        return per_time
    load = np.abs(np.array([e["load_n"] for e in per_time], dtype=np.float64))
    down = unloading_branch(load)
    # unloaded before the first load: the reference is zero, and any round-off on the other side
    # (a spring at 1e-7 N, a micron of pose) read as an infinite error; against the history's peak
    before = (np.maximum.accumulate(load) == 0.0) & (load.max() > 0.0)

    def running_peak(values: list[float]) -> np.ndarray:
        peak = np.fmax.accumulate(values)
        return np.where(before, peak.max(), peak)

    peaks = {b: running_peak([abs(float(e[b])) for e in per_time]) for _, _, b in _CYCLE_PEAK_ERRORS}
    disp_peak = running_peak([float(np.linalg.norm(e["displacement_b_mm"])) for e in per_time])
    has_field = all("pressure_l2_reference_norm" in e for e in per_time)
    field_peak = running_peak([e["pressure_l2_reference_norm"] for e in per_time]) if has_field else None
    out = []
    for k, entry in enumerate(per_time):
        entry = dict(entry)
        if down[k] or before[k]:
            for error, a, b in _CYCLE_PEAK_ERRORS:
                entry[error] = signed_relative_error(float(entry[a]), float(entry[b])) if peaks[b][k] == 0.0 else (float(entry[a]) - float(entry[b])) / peaks[b][k]
            u_a, u_b = np.asarray(entry["displacement_a_mm"]), np.asarray(entry["displacement_b_mm"])
            magnitude = float(np.linalg.norm(u_a - u_b)) / disp_peak[k] if disp_peak[k] > 0.0 else relative_error(u_a, u_b)
            entry["displacement_rel_error"] = -magnitude if np.linalg.norm(u_a) < np.linalg.norm(u_b) else magnitude
            if field_peak is not None and field_peak[k] > 0.0:
                entry["pressure_l2_rel_error"] = entry["pressure_l2_misfit_norm"] / field_peak[k]
            entry["relative_to"] = "cycle peak" if down[k] else "history peak"
        out.append(entry)
    return out


def largest_magnitude(values) -> float:
    """The value of largest magnitude, its sign kept (the worst of a signed error over time points)."""
    values = [float(v) for v in values]
    return max(values, key=abs)


def l2_relative_error(values: np.ndarray, reference: np.ndarray, weights: np.ndarray | None = None) -> float:
    """sqrt(sum w (v - r)^2 / sum w r^2): the L2 relative error of a field on common points (docs/method.md#7-comparison-metrics).

    ``weights`` are the quadrature weights of the points (e.g. the spring areas in mm^2); equal
    weights by default. A zero reference field gives 0 if the values vanish too, +inf otherwise.
    """
    values = np.asarray(values, dtype=np.float64)
    reference = np.asarray(reference, dtype=np.float64)
    w = np.ones_like(reference) if weights is None else np.asarray(weights, dtype=np.float64)
    num = float(np.sum(w * (values - reference) ** 2))
    den = float(np.sum(w * reference**2))
    if den == 0.0:
        return 0.0 if num == 0.0 else math.inf
    return math.sqrt(num / den)


# ---------------------------------------------------------------------------------------------
# Projection onto a triangulated surface


@dataclass(frozen=True)
class Projection:
    """Closest points of destination points on a triangulated surface."""

    triangle: np.ndarray  # (n,) index of the triangle holding the closest point
    barycentric: np.ndarray  # (n, 3) weights of that triangle's vertices
    point_mm: np.ndarray  # (n, 3) the closest point
    distance_mm: np.ndarray  # (n,)


def project_onto_surface(
    points_src: np.ndarray,
    triangles_src: np.ndarray,
    points_dst: np.ndarray,
    *,
    candidates: int = 8,
    chunk_pairs: int = 2_000_000,
) -> Projection:
    """Closest point of every destination point on the source triangulated surface (exact).

    Candidates are the triangles with the nearest centroids (scipy cKDTree). The best candidate
    is certified when the k-th nearest centroid is farther than its distance plus the largest
    centroid-to-vertex radius of any triangle (no other triangle can then be closer); points
    that are not certified are retried with twice as many candidates, up to every triangle.
    """
    from scipy.spatial import cKDTree

    vertices = np.asarray(points_src, dtype=np.float64)
    tris = np.asarray(triangles_src, dtype=np.int64).reshape(-1, 3)
    dst = np.asarray(points_dst, dtype=np.float64).reshape(-1, 3)
    n_tri, n_dst = tris.shape[0], dst.shape[0]
    if n_tri == 0:
        raise ValueError("the source surface has no triangles")
    a, b, c = vertices[tris[:, 0]], vertices[tris[:, 1]], vertices[tris[:, 2]]
    centroids = (a + b + c) / 3.0
    radius = float(np.sqrt(np.max(np.stack([((x - centroids) ** 2).sum(axis=1) for x in (a, b, c)]))))
    tree = cKDTree(centroids)

    triangle = np.zeros(n_dst, dtype=np.int64)
    weights = np.zeros((n_dst, 3))
    dist2 = np.zeros(n_dst)
    pending = np.arange(n_dst)
    k = min(max(int(candidates), 1), n_tri)
    while pending.size:
        step = max(1, chunk_pairs // k)
        still = []
        for lo in range(0, pending.size, step):
            idx_pts = pending[lo : lo + step]
            p = dst[idx_pts]
            d_c, idx = tree.query(p, k=k)
            d_c, idx = d_c.reshape(len(p), k), idx.reshape(len(p), k)
            d2, w = closest_points_on_triangles(p[:, None, :], a[idx], b[idx], c[idx])
            best = np.argmin(d2, axis=1)
            rows = np.arange(len(p))
            d_best = np.sqrt(d2[rows, best])
            certified = (k == n_tri) | (d_c[:, -1] - radius >= d_best)
            take = idx_pts[certified]
            triangle[take] = idx[rows, best][certified]
            weights[take] = w[rows, best][certified]
            dist2[take] = d2[rows, best][certified]
            still.append(idx_pts[~certified])
        pending = np.concatenate(still) if still else np.zeros(0, np.int64)
        k = min(2 * k, n_tri)
    point = np.einsum("ij,ijk->ik", weights, vertices[tris[triangle]])
    return Projection(triangle, weights, point, np.sqrt(dist2))


def sample_onto(
    points_src: np.ndarray,
    triangles_src: np.ndarray,
    values_src_at_vertices: np.ndarray,
    points_dst: np.ndarray,
) -> np.ndarray:
    """Nodal values of the source surface interpolated at the projections of ``points_dst``.

    Each destination point is projected onto the closest point of the source triangulated
    surface and the vertex values of that triangle are interpolated barycentrically: exact for
    fields linear on each triangle (P1, e.g. FE nodal pressure), for destination points on the
    surface. ``values`` may be (n_vertices,) or (n_vertices, m).
    """
    values = np.asarray(values_src_at_vertices, dtype=np.float64)
    proj = project_onto_surface(points_src, triangles_src, points_dst)
    corner = values[np.asarray(triangles_src, dtype=np.int64).reshape(-1, 3)[proj.triangle]]  # (n, 3, ...)
    return np.einsum("ij,ij...->i...", proj.barycentric, corner)


def sample_cells_onto(
    points_src: np.ndarray,
    triangles_src: np.ndarray,
    values_src_at_cells: np.ndarray,
    points_dst: np.ndarray,
) -> np.ndarray:
    """Cell values (piecewise constant) of the triangle holding the closest point of each point."""
    values = np.asarray(values_src_at_cells, dtype=np.float64)
    proj = project_onto_surface(points_src, triangles_src, points_dst)
    return values[proj.triangle]


# ---------------------------------------------------------------------------------------------
# Two result directories


def _scalars(series: dict[str, np.ndarray], k: int) -> dict[str, Any]:
    return {
        "peak": float(series["peak_pressure_mpa"][k]),
        "mean": float(series["mean_pressure_mpa"][k]),
        "area": float(series["contact_area_mm2"][k]),
        "disp": np.array([series[f"disp_{x}_mm"][k] for x in "xyz"], dtype=np.float64),
        "load": float(np.linalg.norm([series[f"force_{x}_n"][k] for x in "xyz"])),
    }


#: summary.json key of a result whose surface is not M but is mapped onto it (the FE contact face of
#: fem_reference.scene_run, bonded to M): its contact area measured on M, one value per time point
AREA_ON_MOBILE_KEY = "contact_area_on_mobile_mm2"


def measured_on_mobile(result) -> bool:
    """Whether a result directory carries its area and pressure measured on M too (an FE
    reference bonded to M: a per-time-point AREA_ON_MOBILE_KEY list and PRESSURE_ON_MOBILE point
    data, looked for on the first map; :func:`series_on_mobile` refuses a later map without it)."""
    areas = result.summary.get(AREA_ON_MOBILE_KEY)
    return (isinstance(areas, list) and len(areas) == len(result.time_s) and len(result.frames) > 0
            and PRESSURE_ON_MOBILE in result.frame(0).point_data)


def series_on_mobile(result) -> dict[str, np.ndarray]:
    """The time series (timeseries.csv columns) of a result measured on M too
    (:func:`measured_on_mobile`) with peak, mean and area taken on M: the area from the summary,
    the peak the largest nodal force per area of M of each map, the mean the same contact force
    over the area on M."""
    series = dict(result.timeseries)
    area = np.asarray(result.summary[AREA_ON_MOBILE_KEY], dtype=np.float64)
    peak = np.empty(len(area))
    for k in range(len(area)):
        frame = result.frame(frame_index(result, k))
        if PRESSURE_ON_MOBILE not in frame.point_data:
            raise InputError(f"the pressure map of time point {k} has no {PRESSURE_ON_MOBILE} point data", file=result.path / "pressure.pvd",
                             expected="the point data of every map, as the first map has it")
        peak[k] = float(np.max(frame.point_data[PRESSURE_ON_MOBILE], initial=0.0))
    force = np.asarray(series["mean_pressure_mpa"], dtype=np.float64) * np.asarray(series["contact_area_mm2"], dtype=np.float64)
    mean = np.divide(force, area, out=np.zeros_like(area), where=area > 0)
    series.update(peak_pressure_mpa=peak, mean_pressure_mpa=mean, contact_area_mm2=area)
    return series


def reference_series(a, b) -> tuple[dict[str, np.ndarray], bool]:
    """b's time series as it is compared with a, and whether on M: the springs live on M, so
    against a reference that maps its own surface onto M (the FE contact face, whose columns fan
    out by (R + t) / R on a cylinder) b's area and pressures are taken on M; two such references
    are compared on their own surfaces."""
    on_mobile = measured_on_mobile(b) and not measured_on_mobile(a)
    return (series_on_mobile(b) if on_mobile else b.timeseries), on_mobile


def pressure_at_cells(frame) -> np.ndarray:
    """Cell pressure of a frame: its cell data, else the mean of its nodal values per triangle."""
    if "pressure_mpa" in frame.cell_data:
        return frame.cell_data["pressure_mpa"]
    if "pressure_mpa" in frame.point_data:
        return frame.point_data["pressure_mpa"][frame.triangles].mean(axis=1)
    raise ValueError("the surface has no pressure_mpa array")


def same_mesh(frame_a, frame_b) -> bool:
    """Whether two frames share their triangulation (same springs, e.g. EDEM and DEM of one scene)."""
    return frame_a.triangles.shape == frame_b.triangles.shape and frame_a.points_mm.shape == frame_b.points_mm.shape and bool(
        np.array_equal(frame_a.triangles, frame_b.triangles)
    )


def field_error(frame_a, frame_b, max_distance_mm: float | None = None, pressure_b: str = "pressure_mpa") -> dict[str, float]:
    """L2 relative error of a's pressure against b's at a's spring centroids (docs/method.md#7-comparison-metrics).

    a's points are the centroids of its non-degenerate triangles (the EDEM springs), weighted by
    their areas. When b has nodal pressure (FE point data) it is interpolated at the projections
    of those points onto b's surface (:func:`sample_onto`); when b only has cell pressure on the
    same triangulation (another run of the same scene, or a closed form) each spring is paired
    with itself, whatever the two poses; otherwise b's cell value at the projection is used.
    Points farther than ``max_distance_mm`` from their partner are left out (all kept by default).

    When b is another surface and a's frame has spring lengths (``spring_length_mm``, an EDEM/DEM
    run), each spring is sampled at its far end, centroid + length x normal (the point of F its
    ray hit, where an FE slab's contact face lies), not at its centroid: on a curved M the
    closest point of that face to the centroid is off the spring's line by up to h tan(angle).
    Springs without a hit (length 0) are sampled at their centroids.
    ``pressure_b``: b's nodal field to sample (PRESSURE_ON_MOBILE: b's force per area of M).
    """
    areas = frame_a.areas_mm2
    keep = areas > 0.0
    points = frame_a.centroids_mm[keep]
    try:
        p_a = pressure_at_cells(frame_a)[keep]
    except ValueError:
        raise InputError("the surface of side a has no pressure_mpa array", expected="cell or point data pressure_mpa") from None
    shared = same_mesh(frame_a, frame_b)
    sampled_at = "spring centroids"
    if not shared and "spring_length_mm" in frame_a.cell_data:
        length = frame_a.cell_data["spring_length_mm"][keep]
        if np.any(length > 0):
            tri = frame_a.triangles[keep]
            a, b, c = (frame_a.points_mm[tri[:, i]] for i in range(3))
            normal = np.cross(b - a, c - a)
            normal /= np.linalg.norm(normal, axis=1)[:, None]
            points = points + length[:, None] * normal
            sampled_at = "spring ends (centroid + length x normal)"
    if pressure_b in frame_b.point_data:
        proj = project_onto_surface(frame_b.points_mm, frame_b.triangles, points)
        corner = frame_b.point_data[pressure_b][frame_b.triangles[proj.triangle]]
        p_b, distance, source = np.einsum("ij,ij->i", proj.barycentric, corner), proj.distance_mm, "point"
    elif "pressure_mpa" in frame_b.cell_data and shared:
        p_b = frame_b.cell_data["pressure_mpa"][keep]
        distance, source = np.linalg.norm(frame_b.centroids_mm[keep] - points, axis=1), "cell (same springs)"
    elif "pressure_mpa" in frame_b.cell_data:
        proj = project_onto_surface(frame_b.points_mm, frame_b.triangles, points)
        p_b, distance, source = frame_b.cell_data["pressure_mpa"][proj.triangle], proj.distance_mm, "cell"
    else:
        raise InputError("the surface of side b has no pressure_mpa array", expected="cell or point data pressure_mpa")
    common = np.ones(points.shape[0], bool) if max_distance_mm is None else distance <= max_distance_mm
    weights = areas[keep][common]
    return {
        "pressure_l2_rel_error": l2_relative_error(p_a[common], p_b[common], weights),
        "pressure_l2_reference_norm": float(np.sqrt(np.sum(weights * p_b[common] ** 2))),
        "pressure_l2_misfit_norm": float(np.sqrt(np.sum(weights * (p_a[common] - p_b[common]) ** 2))),
        "n_common_points": int(common.sum()),
        "max_projection_distance_mm": float(distance.max(initial=0.0)),
        "b_pressure_source": source,
        "a_sampled_at": sampled_at,
    }


def compare_result_dirs(a_dir: str | Path, b_dir: str | Path, *, max_distance_mm: float | None = None) -> dict[str, Any]:
    """The comparison metrics (docs/method.md#7-comparison-metrics) of result directory a against the reference b (both in the docs/result-format.md layout).

    When both have the same time points every time point is compared and each metric is the
    largest over them (``per_time`` keeps them all); when b's time points are a subset of a's
    (an FE reference solved at selected instants of a series) those are compared; otherwise the
    last time points are.
    Scalars come from timeseries.csv; the pressure field from the pressure_NNNN.vtp files, b
    sampled at a's spring centroids (point data when b has it, e.g. FE nodal pressure, else cell
    data). Also returned: both wall times (summary.json) and the sampling distances.
    """
    a, b = read_result_dir(a_dir), read_result_dir(b_dir)
    ta, tb = a.time_s, b.time_s
    same = ta.shape == tb.shape and np.allclose(ta, tb, rtol=1e-9, atol=1e-12) and len(a.frames) == len(b.frames) == len(ta)
    subset = None if same else matching_time_points(ta, tb)
    if same:
        pairs, mode = [(k, k) for k in range(len(ta))], "each time point"
    elif subset is not None:
        pairs, mode = list(zip(subset, range(len(tb)))), "b's time points"
    else:
        pairs, mode = [(len(ta) - 1, len(tb) - 1)], "last time point"
    series_b, on_mobile = reference_series(a, b)
    per_time = []
    for ka, kb in pairs:
        sa, sb = _scalars(a.timeseries, ka), _scalars(series_b, kb)
        frame_a, frame_b = a.frame(frame_index(a, ka)), b.frame(frame_index(b, kb))
        reg_a, reg_b = surface_regularised_peak_mpa(frame_a), surface_regularised_peak_mpa(frame_b)
        entry: dict[str, Any] = {
            "time_a_s": float(ta[ka]),
            "time_b_s": float(tb[kb]),
            "load_n": sb["load"],
            "regularised_peak_pressure_a_mpa": reg_a,
            "regularised_peak_pressure_b_mpa": reg_b,
            "regularised_peak_pressure_rel_error": peak_pressure_error(reg_a, reg_b),
            "peak_pressure_a_mpa": sa["peak"],
            "peak_pressure_b_mpa": sb["peak"],
            "mean_pressure_a_mpa": sa["mean"],
            "mean_pressure_b_mpa": sb["mean"],
            "contact_area_a_mm2": sa["area"],
            "contact_area_b_mm2": sb["area"],
            "displacement_a_mm": sa["disp"].tolist(),
            "displacement_b_mm": sb["disp"].tolist(),
            "peak_pressure_rel_error": peak_pressure_error(sa["peak"], sb["peak"]),
            "mean_pressure_rel_error": mean_pressure_error(sa["mean"], sb["mean"]),
            "contact_area_rel_error": contact_area_error(sa["area"], sb["area"]),
            "displacement_rel_error": displacement_error(sa["disp"], sb["disp"]),
        }
        entry.update(field_error(frame_a, frame_b, max_distance_mm,
                                 PRESSURE_ON_MOBILE if on_mobile else "pressure_mpa"))
        per_time.append(entry)
    per_time = against_cycle_peak(per_time)
    metrics = {name: largest_magnitude(e[name] for e in per_time) for name in COMPARISON_METRICS}
    return {
        "a": str(a.path),
        "b": str(b.path),
        "a_method": a.summary.get("method"),
        "b_method": b.summary.get("method"),
        "a_scene": a.summary.get("scene"),
        "b_scene": b.summary.get("scene"),
        "mode": mode,
        "b_measured_on": "M (b's area and pressure mapped onto the mobile surface, where a's springs live)" if on_mobile else "b's own surface",
        "metrics": metrics,
        "wall_time_a_s": float(a.summary.get("wall_time_s", math.nan)),
        "wall_time_b_s": float(b.summary.get("wall_time_s", math.nan)),
        "n_common_points": min(e["n_common_points"] for e in per_time),
        "max_projection_distance_mm": max(e["max_projection_distance_mm"] for e in per_time),
        "per_time": per_time,
        "peak_load_index": int(np.argmax([e["load_n"] for e in per_time])),
        "warnings": scene_differences(a_dir, b_dir),
    }


def scene_differences(a_dir: str | Path, b_dir: str | Path) -> list[str]:
    """What makes two runs not like for like: different ligaments or constraints in their resolved
    scenes (scene.toml, edem.resultdir.provenance), or ligaments on one side of an FE
    comparison (the FE models none). Empty when they match or a directory has no resolved scene."""
    import tomllib

    from edem.resultdir import SCENE_FILE, read_result_dir

    scenes, methods = [], []
    for directory in (a_dir, b_dir):
        path = Path(directory) / SCENE_FILE
        try:
            scenes.append(tomllib.loads(path.read_text(encoding="utf-8")))
        except (OSError, tomllib.TOMLDecodeError):
            return []
        methods.append(str(read_result_dir(directory).summary.get("method", "")))
    ligaments = [sorted((str(l.get("name", "")), l.get("youngs_modulus_mpa"), l.get("area_mm2")) for l in s.get("ligaments", [])) for s in scenes]
    fixed = [sorted(s.get("constraints", {}).get("fixed_dofs", [])) for s in scenes]
    out = []
    for k, (method, ligs) in enumerate(zip(methods, ligaments)):
        if method.startswith("fe-") and ligaments[1 - k]:
            out.append(f"{'ab'[k]} is the FE reference, which models no ligaments; {'ab'[1 - k]} has {len(ligaments[1 - k])} "
                       f"({', '.join(n for n, *_ in ligaments[1 - k])}): not like for like (remove the [[ligaments]] tables of the scene)")
    if not any(m.startswith("fe-") for m in methods) and ligaments[0] != ligaments[1]:
        out.append(f"the ligaments differ: a has {[n for n, *_ in ligaments[0]] or 'none'}, b has {[n for n, *_ in ligaments[1]] or 'none'} (or their moduli or areas)")
    if fixed[0] != fixed[1]:
        out.append(f"the constraints differ: a fixes {fixed[0] or 'nothing'}, b fixes {fixed[1] or 'nothing'}")
    return out


def matching_time_points(time_a: np.ndarray, time_b: np.ndarray) -> list[int] | None:
    """Indices into ``time_a`` of every time of ``time_b`` when each one is there (to 1e-9), else None."""
    ta, tb = np.asarray(time_a, dtype=np.float64), np.asarray(time_b, dtype=np.float64)
    if tb.size == 0 or ta.size <= tb.size:
        return None
    out = []
    for t in tb:
        k = int(np.argmin(np.abs(ta - t)))
        if not math.isclose(ta[k], t, rel_tol=1e-9, abs_tol=1e-12):
            return None
        out.append(k)
    return out


def frame_index(result, k: int) -> int:
    """Index into ``result.frames`` of time point k: k when every time point has a pressure map,
    else the map written at that time (result directories may hold maps of some time points only)."""
    n = len(result.time_s)
    k = k % n
    if len(result.frames) == n:
        return k
    times = np.array([t for t, _ in result.frames])
    j = int(np.argmin(np.abs(times - result.time_s[k])))
    if not math.isclose(times[j], result.time_s[k], rel_tol=1e-9, abs_tol=1e-12):
        raise InputError(f"no pressure map at t = {result.time_s[k]:g} s", file=result.path / "pressure.pvd", expected="a <DataSet> at every compared time point")
    return j


#: summary values of one side's time series, reported with the prefix a_ or b_ (verification.campaigns.METRICS)
SERIES_METRICS = (
    "regularised_peak_pressure_mpa",
    "peak_pressure_mpa",
    "mean_contact_area_mm2",
    "max_superior_displacement_mm",
    "max_superior_displacement_percent",
    "displacement_norm_mm",
)


#: centre-of-pressure summaries of side a (DEM/EDEM result directories write cop_*_mm columns)
COP_METRICS = {
    "a_cop_x_mm": "side a: contact-force-weighted mean over the time points of the centre of pressure's x (mm)",
    "a_cop_y_mm": "side a: contact-force-weighted mean over the time points of the centre of pressure's y (mm)",
}


def cop_metrics(series: dict[str, np.ndarray]) -> dict[str, float]:
    """:data:`COP_METRICS` from a timeseries with cop_x_mm / cop_y_mm columns: each time point's
    centre of pressure weighted by its contact force (mean pressure x contact area)."""
    weight = np.asarray(series["mean_pressure_mpa"], float) * np.asarray(series["contact_area_mm2"], float)
    if not weight.sum() > 0.0:
        weight = np.ones_like(weight)
    return {f"a_cop_{x}_mm": float(np.average(np.asarray(series[f"cop_{x}_mm"], float), weights=weight)) for x in "xy"}


#: the series column :func:`with_regularised_peak` adds (not a timeseries.csv column: computed from the maps)
REGULARISED_PEAK_COLUMN = "regularised_peak_pressure_mpa"


def with_regularised_peak(series: dict[str, np.ndarray], result) -> dict[str, np.ndarray]:
    """``series`` (a result's time series, e.g. :func:`reference_series`) with the column
    REGULARISED_PEAK_COLUMN: the regularised peak of each time point's pressure map
    (:func:`edem.pressure_metrics.surface_regularised_peak_mpa`, as summary.json's
    regularised_peak_pressure_mpa), when every time point has one; unchanged otherwise."""
    n = len(series["time_s"])
    if len(result.frames) != n or len(result.time_s) != n:
        return series
    try:
        peaks = np.array([surface_regularised_peak_mpa(result.frame(k)) for k in range(n)])
    except ValueError:  # maps without pressure
        return series
    return {**series, REGULARISED_PEAK_COLUMN: peaks}


def series_metrics(series: dict[str, np.ndarray], prefix: str = "") -> dict[str, float]:
    """Summary values of a time series (timeseries.csv columns), keys prefixed with ``prefix``.

    peak_pressure_mpa: the largest raw peak pressure over the time points;
    regularised_peak_pressure_mpa: the largest regularised peak (when the series has the column
    of :func:`with_regularised_peak`); mean_contact_area_mm2:
    the mean contact area over them; max_superior_displacement_mm: the largest displacement of G
    along +z (superior in the scene's axes) and ..._percent: when, in % of the time span (0 for a
    single time point); displacement_norm_mm: |u| of G at the last time point.
    """
    time = np.asarray(series["time_s"], dtype=np.float64)
    z = np.asarray(series["disp_z_mm"], dtype=np.float64)
    k = int(np.argmax(z))
    span = float(time[-1] - time[0])
    last = np.array([series[f"disp_{x}_mm"][-1] for x in "xyz"], dtype=np.float64)
    values = {
        "peak_pressure_mpa": float(np.max(series["peak_pressure_mpa"])),
        **({"regularised_peak_pressure_mpa": float(np.max(series[REGULARISED_PEAK_COLUMN]))} if REGULARISED_PEAK_COLUMN in series else {}),
        "mean_contact_area_mm2": float(np.mean(series["contact_area_mm2"])),
        "max_superior_displacement_mm": float(z[k]),
        "max_superior_displacement_percent": 100.0 * float(time[k] - time[0]) / span if span > 0 else 0.0,
        "displacement_norm_mm": float(np.linalg.norm(last)),
    }
    return {prefix + name: value for name, value in values.items()}


def format_metrics_table(comparison: dict[str, Any]) -> str:
    """Plain-text table of a :func:`compare_result_dirs` result (what `edem compare` prints)."""
    per_time = comparison["per_time"]
    last = per_time[comparison.get("peak_load_index", len(per_time) - 1)]  # the headline instant: the peak load
    rows = [
        ("regularised peak (MPa)", last["regularised_peak_pressure_a_mpa"], last["regularised_peak_pressure_b_mpa"], "regularised_peak_pressure_rel_error"),
        ("raw peak (MPa)", last["peak_pressure_a_mpa"], last["peak_pressure_b_mpa"], "peak_pressure_rel_error"),
        ("mean pressure (MPa)", last["mean_pressure_a_mpa"], last["mean_pressure_b_mpa"], "mean_pressure_rel_error"),
        ("contact area (mm^2)", last["contact_area_a_mm2"], last["contact_area_b_mm2"], "contact_area_rel_error"),
        (
            "displacement |u| (mm)",
            float(np.linalg.norm(last["displacement_a_mm"])),
            float(np.linalg.norm(last["displacement_b_mm"])),
            "displacement_rel_error",
        ),
        ("pressure field (L2)", None, None, "pressure_l2_rel_error"),
    ]
    many = len(comparison["per_time"]) > 1
    head = f"{'quantity':24s} {'a':>12s} {'b':>12s} {'rel. error':>12s}" + (f" {'worst over t':>12s}" if many else "")
    lines = [
        f"a: {comparison['a']} ({comparison['a_method']}, {comparison['wall_time_a_s']:.3g} s)",
        f"b: {comparison['b']} ({comparison['b_method']}, {comparison['wall_time_b_s']:.3g} s), the reference",
        f"compared: {comparison['mode']} ({len(per_time)}); values at the peak-load instant t = {last['time_a_s']:g} s (|F| = {last.get('load_n', math.nan):.4g} N)",
        f"b measured on: {comparison.get('b_measured_on', "b's own surface")}",
        head,
        "-" * len(head),
    ]
    for label, va, vb, key in rows:
        fa = f"{va:12.5g}" if va is not None else f"{'':12s}"
        fb = f"{vb:12.5g}" if vb is not None else f"{'':12s}"
        sign = "" if key == "pressure_l2_rel_error" else "+"  # the L2 error is a norm; the others are signed
        line = f"{label:24s} {fa} {fb} {last[key]:{sign}12.4g}"
        if many:
            line += f" {comparison['metrics'][key]:{sign}12.4g}"
        lines.append(line)
    lines.append(
        f"pressure compared at {comparison['n_common_points']} spring centroids of a "
        f"(b's {comparison['per_time'][-1]['b_pressure_source']} values; largest distance between compared points "
        f"{comparison['max_projection_distance_mm']:.3g} mm)"
    )
    lines += [f"warning: {w}" for w in comparison.get("warnings", [])]
    return "\n".join(lines)
