"""The FE reference's own discretisation error (docs/campaigns.md, ``fe-convergence``).

Three meshes of one FE reference, refined by a constant ratio, give an observed order and a
Richardson extrapolation of each compared quantity; the extrapolated value against each mesh's
value is that mesh's estimated error (:func:`richardson`). The ``fe-convergence`` campaign runs
the study at the quick campaign's FE points and stores the estimates in
:data:`REFERENCE_FILE`, keyed by what the FE side reads (:func:`fe_key`: scene, model, the
overrides the FE reads, mesh size and degree), so that every campaign case whose reference is
one of those FE runs finds its error (:func:`fe_relative_error`). A case whose FE run is not in
the file has no known error, and says so (None).

The quantities are those the comparisons use (verification.metrics, the FE measured on M where
the springs live): the peak pressure (largest nodal pressure per area of M), the contact area on
M, |u| of the bone, and the 98th percentile by area of the contact pressure on M
(:func:`pressure_percentile_by_area`), a peak that one node cannot set.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from geometries.triangle_kernels import triangle_areas

#: the stored study (written by ``edem verify fe-convergence --refresh-reference``)
REFERENCE_FILE = Path(__file__).resolve().parent / "references" / "fe_convergence.json"
#: the observed order is believed (the meshes in the asymptotic range) inside these bounds; P2's
#: nominal orders are 3 (displacement, L2) and 2 (energy, stresses): a quantity converging
#: faster than 4 or slower than 0.5 is not behaving like its leading error term
ORDER_RANGE = (0.5, 4.0)
#: the quantities of the study: name -> (value metric of the FE side, comparison metric whose FE error it is)
QUANTITIES = {
    "regularised peak pressure": ("fe_regularised_peak_pressure_mpa", "regularised_peak_pressure_rel_error"),
    "peak pressure": ("fe_peak_pressure_mpa", "peak_pressure_rel_error"),
    "p98 pressure": ("fe_p98_pressure_mpa", "p98_pressure_rel_error"),
    "contact area": ("fe_contact_area_mm2", "contact_area_rel_error"),
    "displacement": ("fe_displacement_norm_mm", "displacement_rel_error"),
}
#: the metrics an FE side reports about itself in this study (:func:`fe_values`)
FE_VALUE_METRICS = ("fe_regularised_peak_pressure_mpa", "fe_peak_pressure_mpa", "fe_p98_pressure_mpa", "fe_contact_area_mm2", "fe_displacement_norm_mm",
                    "fe_n_dofs", "fe_wall_time_s", "fe_peak_memory_mb")
FE_VALUE_DESCRIPTIONS = {
    "fe_regularised_peak_pressure_mpa": "FE side: regularised peak pressure on M at the last time point (the largest mean over 1 mm^2, edem.pressure_metrics: the judged peak)",
    "fe_peak_pressure_mpa": "FE side: largest nodal pressure per area of M at the last time point (the peak the comparisons use)",
    "fe_p98_pressure_mpa": "FE side: 98th percentile by area of the contact pressure on M (verification.fe_convergence.pressure_percentile_by_area)",
    "fe_contact_area_mm2": "FE side: contact area on M at the last time point",
    "fe_displacement_norm_mm": "FE side: |u| of the bone at the last time point",
    "fe_n_dofs": "FE side: degrees of freedom of the solve",
    "fe_wall_time_s": "FE side: wall time of the run (summary.json)",
    "fe_peak_memory_mb": "FE side: peak resident memory of the run (summary.json peak_memory_mb)",
}


@dataclass(frozen=True)
class Richardson:
    """The Richardson estimate of one quantity on three meshes (coarsest first)."""

    sizes: tuple[float, ...]  # mesh sizes, coarsest first
    values: tuple[float, ...]
    order: float  # observed order (nan when the differences do not shrink monotonically)
    extrapolated: float | None  # the h -> 0 value (None outside the asymptotic range)
    asymptotic: bool  # the order inside ORDER_RANGE and the differences of one sign
    errors: tuple[float, ...]  # estimated relative error of each mesh's value

    def to_dict(self) -> dict[str, Any]:
        order = self.order if math.isfinite(self.order) else None  # JSON has no nan: no observed order
        return {"sizes": list(self.sizes), "values": list(self.values), "order": order, "extrapolated": self.extrapolated,
                "asymptotic": self.asymptotic, "errors": list(self.errors)}


def observed_order(sizes: tuple[float, float, float], values: tuple[float, float, float], *, iterations: int = 200) -> float:
    """The order p of f(h) = f0 + C h^p through three solutions (sizes coarsest first, any ratios).

    With r21 = h2 / h3 and r32 = h1 / h2 (h3 the finest), e21 = f2 - f3, e32 = f1 - f2:
    p = |log|e32 / e21| + q(p)| / log r21 with q(p) = log((r21^p - s) / (r32^p - s)) and
    s = sign(e32 / e21), solved by fixed-point iteration (q = 0 for a constant ratio: one step).
    nan when a difference is zero or the iteration does not settle.
    """
    h1, h2, h3 = sizes
    f1, f2, f3 = values
    e21, e32 = f2 - f3, f1 - f2
    if e21 == 0.0 or e32 == 0.0:
        return math.nan
    r21, r32 = h2 / h3, h1 / h2
    s = 1.0 if e32 / e21 > 0 else -1.0
    base = math.log(abs(e32 / e21))
    p = abs(base) / math.log(r21)
    for _ in range(iterations):
        try:
            q = math.log((r21**p - s) / (r32**p - s))
        except (ValueError, ZeroDivisionError, OverflowError):
            return math.nan
        new = abs(base + q) / math.log(r21)
        if abs(new - p) < 1e-12 * max(1.0, p):
            return new
        p = new
    return math.nan


def richardson(sizes: list[float] | tuple[float, ...], values: list[float] | tuple[float, ...]) -> Richardson:
    """Observed order, extrapolation and per-mesh relative errors of three solutions.

    ``sizes`` h1 > h2 > h3 (the representative element size of each mesh; the ratios need not be
    equal), ``values`` f1, f2, f3. With f(h) = f0 + C h^p: p by :func:`observed_order` and
    f0 = f3 + (f3 - f2) / ((h2 / h3)^p - 1); each mesh's error is |f_i - f0| / |f0|. When the
    two differences differ in sign (oscillation), or p lies outside :data:`ORDER_RANGE`, the
    meshes are not in the asymptotic range: no extrapolation, and each mesh's error is taken as
    the largest relative difference between its value and the other meshes' (what refining has
    been seen to change), stated as such (``asymptotic`` False).
    """
    h = tuple(float(x) for x in sizes)
    f = tuple(float(x) for x in values)
    if len(h) != 3 or len(f) != 3:
        raise ValueError("a Richardson estimate needs three meshes")
    if not h[0] > h[1] > h[2] > 0:
        raise ValueError(f"mesh sizes {h} are not decreasing")
    d12, d23 = f[0] - f[1], f[1] - f[2]
    if d23 == 0.0 and d12 == 0.0:
        return Richardson(h, f, math.inf, f[2], True, (0.0, 0.0, 0.0))
    same_sign = d12 * d23 > 0
    order = observed_order(h, f) if same_sign else math.nan
    asymptotic = same_sign and math.isfinite(order) and ORDER_RANGE[0] <= order <= ORDER_RANGE[1]
    if asymptotic:
        f0 = f[2] + (f[2] - f[1]) / ((h[1] / h[2]) ** order - 1.0)
        scale = abs(f0) if f0 != 0.0 else max(abs(x) for x in f)
        return Richardson(h, f, order, f0, True, tuple(abs(x - f0) / scale for x in f))
    scale = max(abs(f[2]), 1e-300)
    spread = tuple(max(abs(x - y) for y in f) / scale for x in f)
    return Richardson(h, f, order, None, False, spread)


def finest_windows(n_levels: int) -> tuple[int, ...]:
    """For each of ``n_levels`` meshes (coarsest first), the first mesh of the three consecutive
    meshes its error is estimated from: the finest three that contain it (min(i, n - 3)).

    Three meshes are one estimate for all. A study that adds a finer mesh (a point whose three
    meshes were not asymptotic) estimates every mesh but the coarsest from the finest three: they
    are the nearest to the asymptotic range, and a mesh's error is what refining it further
    changes, not how far a coarser mesh was from it (the coarsest keeps the first three).
    """
    if n_levels < 3:
        raise ValueError("a Richardson estimate needs three meshes")
    return tuple(min(i, n_levels - 3) for i in range(n_levels))


def representative_sizes(dofs: list[float] | tuple[float, ...], in_plane: bool = False) -> tuple[float, ...]:
    """The representative element size of each mesh from its DOFs: h ~ N^(-1/d), d the number of
    directions the meshes are refined in. d = 3 in general (the study's levels refine in plane and
    through the thickness at once); d = 2 for meshes that keep the same elements through a layer
    and only halve its triangles (``in_plane``): N grows 4x per halving, and N^(-1/3) would read
    a ratio of 1.59 where the triangles' is 2, and every observed order 1.5x too high."""
    exponent = 0.5 if in_plane else 1.0 / 3.0
    return tuple(float(n) ** -exponent for n in dofs)


def in_plane_windows(layers: list[int | None] | tuple[int | None, ...]) -> tuple[bool, ...]:
    """Per three-mesh window of :func:`finest_windows` (by its first mesh), whether its meshes
    are refined in plane only: all three set the same ``layers_through_thickness`` (None: the
    mesher's ceil(thickness / size), which changes with the size)."""
    return tuple(layers[j] is not None and layers[j] == layers[j + 1] == layers[j + 2] for j in range(len(layers) - 2))


def level_estimates(dofs: list[float] | tuple[float, ...], values: list[float] | tuple[float, ...],
                    layers: list[int | None] | tuple[int | None, ...] | None = None) -> tuple[Richardson, ...]:
    """Each mesh's Richardson estimate (:func:`richardson`) on the finest three consecutive meshes
    that contain it (:func:`finest_windows`), sizes from the DOFs (:func:`representative_sizes`,
    in plane for a window of one ``layers_through_thickness``, :func:`in_plane_windows`; None:
    every window is a general refinement). Mesh i's error is ``est.errors[i - first]`` of its
    estimate ``est`` whose meshes start at ``first``. ``dofs`` increasing, three or more meshes."""
    if len(dofs) != len(values):
        raise ValueError("one value per mesh")
    return window_estimates(dofs, layers, lambda j, sizes: richardson(sizes, values[j:j + 3]))


def window_estimates(dofs: list[float] | tuple[float, ...], layers: list[int | None] | tuple[int | None, ...] | None,
                     estimate: Callable[[int, tuple[float, ...]], Richardson]) -> tuple[Richardson, ...]:
    """Each mesh's estimate on the finest three consecutive meshes that contain it: ``estimate(j,
    sizes)`` of the three meshes from ``j`` (their :func:`representative_sizes`, in plane for a
    window of one ``layers_through_thickness``), once per window (:func:`level_estimates` of a
    quantity, the analysis's of the pressure field)."""
    firsts = finest_windows(len(dofs))
    flat = in_plane_windows(layers if layers is not None else [None] * len(dofs))
    by_first = {j: estimate(j, representative_sizes(dofs[j:j + 3], flat[j])) for j in set(firsts)}
    return tuple(by_first[j] for j in firsts)


def field_difference(dir_a: str | Path, dir_b: str | Path, k: int = -1) -> float:
    """||p_a - p_b|| / ||p_b||: the L2 relative difference of two FE runs' pressure per area of M
    (PRESSURE_ON_MOBILE, the field the comparisons judge) at their time point ``k`` (default the
    last), on a's triangles (a's corner mean at each centroid against b interpolated at the
    centroid's closest point of b's surface, weighted by a's triangle areas;
    verification.metrics.l2_relative_error)."""
    from edem.pressure_metrics import PRESSURE_ON_MOBILE
    from edem.resultdir import read_result_dir
    from verification.metrics import frame_index, l2_relative_error, project_onto_surface

    frames = []
    for d in (dir_a, dir_b):
        result = read_result_dir(d)
        frames.append(result.frame(frame_index(result, k % len(result.time_s))))
    a, b = frames
    proj = project_onto_surface(b.points_mm, b.triangles, a.centroids_mm)
    p_b = np.einsum("ij,ij->i", proj.barycentric, b.point_data[PRESSURE_ON_MOBILE][b.triangles[proj.triangle]])
    p_a = a.point_data[PRESSURE_ON_MOBILE][a.triangles].mean(axis=1)
    return l2_relative_error(p_a, p_b, a.areas_mm2)


def field_errors(sizes: list[float] | tuple[float, ...], to_finest: tuple[float, float], between_coarse: float) -> Richardson:
    """Each mesh's estimated relative L2 error of the pressure field from its differences.

    ``to_finest``: the L2 differences of the two coarser meshes' fields from the finest's
    (:func:`field_difference`, relative to the finest's norm); ``between_coarse``: that of the
    coarsest from the middle mesh. Near convergence p_h = p* + C h^q e with one shape e, so the
    fields lie on a line: s_h = ||p_h - p_finest|| is affine in h^q and :func:`richardson` on
    (s_1, s_2, 0) gives q and the finest's own offset s_0; each mesh's error is |s_i - s_0|.
    The line needs s_1 = between_coarse + s_2 (to 10 %, or the fields do not move along one
    shape); otherwise, or outside the asymptotic range, each mesh's error is its largest
    difference from the other meshes (what refining has been seen to change), ``asymptotic`` False.
    """
    s1, s2 = (float(x) for x in to_finest)
    est = richardson(sizes, (s1, s2, 0.0))
    on_line = abs(s1 - (s2 + between_coarse)) <= 0.1 * max(s1, 1e-300)
    if est.asymptotic and on_line:
        return Richardson(est.sizes, est.values, est.order, est.extrapolated, True, tuple(abs(x - est.extrapolated) for x in est.values))
    spread = (max(s1, between_coarse), max(s2, between_coarse), max(s1, s2))
    return Richardson(est.sizes, est.values, est.order, None, False, spread)


def pressure_percentile_by_area(pressure_mpa: np.ndarray, vertices_mm: np.ndarray, triangles: np.ndarray, percentile: float = 98.0) -> float:
    """The pressure below which ``percentile`` % of the contact area lies (MPa).

    ``pressure_mpa`` (n,) nodal values on the triangulated surface (vertices (n, 3) mm, triangles
    (m, 3)); each node carries a third of the area of its triangles (lumped), and the contact is
    the nodes with p > 0. Unlike the largest nodal value, one node (a rim, a single element)
    cannot set it: it moves only when the pressure of ``100 - percentile`` % of the area does.
    """
    p = np.asarray(pressure_mpa, dtype=np.float64)
    tri = np.asarray(triangles)
    v = np.asarray(vertices_mm, dtype=np.float64)
    area = triangle_areas(v[tri[:, 0]], v[tri[:, 1]], v[tri[:, 2]])
    node_area = np.bincount(tri.ravel(), weights=np.repeat(area / 3.0, 3), minlength=len(p))
    contact = p > 0
    if not np.any(contact):
        return 0.0
    order = np.argsort(p[contact])
    ps, w = p[contact][order], node_area[contact][order]
    cumulative = np.cumsum(w) / np.sum(w)
    return float(ps[min(int(np.searchsorted(cumulative, percentile / 100.0)), len(ps) - 1)])


def fe_values(result_dir: str | Path, k: int = -1) -> dict[str, float]:
    """The study's quantities of one FE result directory, at its time point ``k`` (default the
    last), measured as the comparisons measure them (on M, verification.metrics.series_on_mobile),
    and its cost (of the whole run)."""
    from edem.pressure_metrics import surface_regularised_peak_mpa
    from edem.resultdir import read_result_dir
    from verification.metrics import PRESSURE_ON_MOBILE, frame_index, measured_on_mobile, series_on_mobile

    result = read_result_dir(result_dir)
    on_mobile = measured_on_mobile(result)
    series = series_on_mobile(result) if on_mobile else result.timeseries
    k = k % len(result.time_s)
    frame = result.frame(frame_index(result, k))
    pressure = frame.point_data[PRESSURE_ON_MOBILE if on_mobile else "pressure_mpa"]
    memory = result.summary.get("peak_memory_mb")
    return {
        "fe_regularised_peak_pressure_mpa": surface_regularised_peak_mpa(frame),
        "fe_peak_pressure_mpa": float(series["peak_pressure_mpa"][k]),
        "fe_p98_pressure_mpa": pressure_percentile_by_area(pressure, frame.points_mm, frame.triangles),
        "fe_contact_area_mm2": float(series["contact_area_mm2"][k]),
        "fe_displacement_norm_mm": float(np.linalg.norm([series[f"disp_{x}_mm"][k] for x in "xyz"])),
        "fe_n_dofs": float(result.summary.get("n_dofs", math.nan)),
        "fe_wall_time_s": float(result.summary.get("wall_time_s", math.nan)),
        "fe_peak_memory_mb": math.nan if memory is None else float(memory),
    }


# ---------------------------------------------------------------------------------------------
# The stored study and its lookup


def fe_key(scene: str, side: str, overrides: dict[str, Any], options: dict[str, Any]) -> str:
    """The key of one FE reference run: scene, side (fe-slab / fe-layer), the overrides and the
    options the FE side reads (verification.sides.side_inputs), as canonical JSON."""
    from verification.sides import side_inputs

    kept, read = side_inputs(side, dict(overrides), dict(options))
    kept = {k: v for k, v in kept.items() if not _scene_says(scene, k, v)}
    read.pop("steps", None)
    settings = {k: (float(v) if k == "mesh_size_mm" else v) for k, v in read.items()}
    return json.dumps({"scene": scene, "side": side, "overrides": kept, "options": settings}, sort_keys=True, separators=(",", ":"))


def _scene_says(scene: str, dotted: str, value: Any) -> bool:
    """Whether the scene file already sets ``dotted`` to ``value`` (an override that changes
    nothing: the subject campaign's FE run and quick's at the scene's own nu are one run)."""
    from geometries.errors import InputError
    from edem.scene import read_scene_toml, resolve_scene_path

    try:
        table: Any = read_scene_toml(resolve_scene_path(scene))
    except InputError:
        return False
    for name in dotted.split("."):
        if not isinstance(table, dict) or name not in table:
            return False
        table = table[name]
    return table == value


def load_reference(path: str | Path | None = None) -> dict[str, Any]:
    """The stored study (:data:`REFERENCE_FILE`); an empty one when the file does not exist."""
    file = Path(path) if path is not None else REFERENCE_FILE
    if not file.exists():
        return {"entries": {}}
    from geometries.errors import InputError

    try:
        data = json.loads(file.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot read the FE convergence reference: {exc}", file=str(file), expected="the JSON that edem verify fe-convergence --refresh-reference writes") from None
    if not isinstance(data, dict) or not isinstance(data.get("entries"), dict):
        raise InputError("no 'entries' table", file=str(file), key="entries", expected="FE key -> {errors: {metric: relative error}}")
    return data


def fe_relative_error(case: Any, reference: dict[str, Any] | None = None) -> dict[str, float] | None:
    """The estimated relative error of the FE reference side of ``case`` (a
    verification.campaign_model.Case, or a campaign's case row: a dict with "scene", "sides"
    (names, or the side records of verification.runner), "overrides" and "options", whose last
    side is an FE side), per comparison metric (``peak_pressure_rel_error``,
    ``p98_pressure_rel_error``, ``contact_area_rel_error``, ``displacement_rel_error``): what a
    band must exceed before it can judge. None when the case has no FE reference or its FE run is
    not in the stored study (its error is unknown)."""
    d = case if isinstance(case, dict) else case.definition()
    sides = tuple(s["side"] if isinstance(s, dict) else s for s in d.get("sides", ()))
    if len(sides) < 2 or not sides[-1].startswith("fe-"):
        return None
    data = load_reference() if reference is None else reference
    entry = data["entries"].get(fe_key(d["scene"], sides[-1], d.get("overrides") or {}, d.get("options") or {}))
    if entry is None:
        return None
    return {metric: float(value) for metric, value in entry["errors"].items()}


def write_reference(summary: dict[str, Any], path: str | Path | None = None) -> Path:
    """Merge the errors of an ``fe-convergence`` campaign summary (its analysis's ``entries`` and
    ``points``) into :data:`REFERENCE_FILE` (or ``path``): each point estimated in the summary
    replaces that point's record and entries (its levels' and its P1 run's), stamped with its own
    ``refreshed_at``; every other stored point stays as it was (a study cut short, or run on a few
    points, refreshes only what it solved; a point it could not estimate leaves no record).
    InputError when the summary holds no estimate (every point unavailable)."""
    import datetime as _dt
    import os

    from geometries.errors import InputError

    result = next((a for a in summary.get("analyses", []) if a.get("kind") == "fe-convergence"), None)
    entries = (result or {}).get("values", {}).get("entries") or {}
    if not entries:
        raise InputError("the fe-convergence campaign produced no error estimate (its FE runs unavailable or failed)", key="analyses",
                         expected="the three meshes of at least one point solved")
    file = Path(path) if path is not None else REFERENCE_FILE
    stored = load_reference(file)
    now = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    before = stored.get("refreshed_at")  # the points stored before per-point dates were refreshed with the whole file
    points = {p["point"]: p if "refreshed_at" in p or before is None else {**p, "refreshed_at": before} for p in stored.get("points", [])}
    fresh = {p["point"]: {**p, "refreshed_at": now} for p in result["values"]["points"] if "unavailable" not in p}
    points.update(fresh)
    kept = {k: e for k, e in stored["entries"].items() if _point_of(e["case"]) not in fresh}  # a fresh point's old entries go, whatever their keys
    data = {
        "what": "estimated relative discretisation error of FE reference runs (edem verify fe-convergence --refresh-reference; verification.fe_convergence); "
                "each point's refreshed_at says when its meshes were estimated, the file's when it was last written",
        "refreshed_at": now,
        "entries": dict(sorted({**kept, **entries}.items())),
        "points": list(points.values()),
    }
    tmp = file.with_name(file.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=1, allow_nan=False) + "\n", encoding="utf-8")
    os.replace(tmp, file)  # an interrupted write leaves the previous file whole
    return file


def _point_of(case_name: str) -> str:
    """The point of a study case (verification.campaigns.fe_convergence: ``<point>-h<size>[-L<layers>]``
    for a level, ``<point>-P1-h<size>`` for quick's P1 run)."""
    return re.sub(r"(-P1)?-h[0-9.]+(-L[0-9]+)?$", "", case_name)


#: what a table cell says for an FE reference whose error is not in the study
UNKNOWN_FE_ERROR = "unknown"


#: the card metrics whose FE error a table cell gives (:func:`fe_error_text`), in its order: the
#: regularised peak, not the raw one, which the campaigns report but do not compare
FE_ERROR_TEXT_METRICS = ("regularised_peak_pressure_rel_error", "contact_area_rel_error", "displacement_rel_error", "pressure_l2_rel_error")


def fe_error_text(errors: dict[str, float] | None) -> str:
    """One cell of a campaign table: the FE's own estimated errors (regularised peak / area / |u| /
    L2, :data:`FE_ERROR_TEXT_METRICS`), or that they are unknown (the run is not in the
    fe-convergence study)."""
    if errors is None:
        return UNKNOWN_FE_ERROR
    return " / ".join(f"{100.0 * errors[m]:.1f} %" if m in errors else "–" for m in FE_ERROR_TEXT_METRICS)


def time_point_count(result_dir: str | Path) -> int:
    """How many time points an FE result directory holds (timeseries.csv)."""
    from edem.resultdir import read_result_dir

    return len(read_result_dir(result_dir).time_s)
