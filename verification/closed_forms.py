"""Closed-form solutions of the discrete method, as functions of a scene (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs, docs/method.md#2-edem-the-time-dependent-incremental-method, docs/method.md#8-built-in-geometries, docs/method.md#7-comparison-metrics).

Each closed form reads what it needs from the scene (material, law, load, constraints, the
spring centroids) and from the parameters of its built-in geometry generator, checks that the
scene is one it solves (else InputError naming the key), and returns a
:class:`ClosedFormSolution`: per time point the displacement of the mobile body, the docs/method.md#7-comparison-metrics
scalars and the pressure field at the spring centroids. :func:`write_closed_form_results`
writes it as a result directory (docs/result-format.md), so a closed form is compared with a run exactly like an
FE reference (:func:`verification.metrics.compare_result_dirs`).

With E' = E (1 - nu) / ((1 + nu)(1 - 2 nu)) (eq. 3.7), a spring of length h under a rigid
approach d along its normal carries p = E' d / h (threshold law):

* flat-plates: parallel plates at gap h, plate area A: p = F / A, d = F h / (E' A);
* tilted-plane: h(x) = g + x tan(a), rotations fixed: p(x) = E' d / h(x) with
  F = E' d D int dx / h(x) = E' d D ln(h(W/2) / h(-W/2)) / tan(a);
* cylinder-plane: cylinder of radius R under a plane at gap g, rays radial,
  h(phi) = (R + g) / cos(phi) - R, contact where h <= h_max, approach d cos(phi):
  p(phi) = E' d cos(phi) / h(phi), F = E' d W R int cos^2(phi) / h(phi) dphi (the discrete
  elastic foundation of the thesis, 3.7, on the exact cylinder);
* log-law: EDEM under a slow monotonic ramp on flat plates, where each increment sees the
  current length h0 - d: dF = E' A dd / (h0 - d), so d = h0 (1 - exp(-F / (E' A))) (docs/method.md#2-edem-the-time-dependent-incremental-method);
* hemisphere-thickness: concentric hemispheres (thesis 4.2.2): every spring length is
  R_t - R; rotations fixed, p(theta) = E' d cos(theta) / t with d = 3 F t / (2 pi R^2 E').
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from geometries.errors import InputError
from edem.mechanics import confined_modulus_mpa
from edem.resultdir import Frame, SurfaceFrame, timeseries_row, write_result_dir
from edem.scene import Scene, apply_overrides, load_scene, resolve_scene_path
from geometries.builders import build_geometry, builder_names


@dataclass(frozen=True)
class ClosedFormSolution:
    """What a closed form predicts at each time point of a scene (the quantities of docs/method.md#7-comparison-metrics)."""

    name: str
    formula: str  # one line: the closed form used
    time_s: np.ndarray  # (n,)
    force_n: np.ndarray  # (n, 3) applied load
    displacement_mm: np.ndarray  # (n, 3) of the mobile body (a translation)
    peak_pressure_mpa: np.ndarray  # (n,)
    mean_pressure_mpa: np.ndarray  # (n,) contact force over contact area
    contact_area_mm2: np.ndarray  # (n,)
    pressure_mpa: np.ndarray  # (n, n_springs) the field at the spring centroids
    in_contact: np.ndarray  # (n, n_springs) bool
    spring_length_mm: np.ndarray  # (n_springs,) exact undeformed spring lengths
    extra: dict[str, Any] = field(default_factory=dict)  # JSON numbers specific to the closed form


# ---------------------------------------------------------------------------------------------
# The scene's geometry parameters and common checks


def geometry_parameters(scene_ref: str | Path, overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """The [geometry] table of a scene (after ``overrides``) as its generator resolves it (the
    defaults of its mode filled in; the build is the one the scene keeps, geometries.builders).

    Returns the parameters with the generator's name under "builtin"; raises InputError for
    scenes built from mesh files (no closed form knows their shape).
    """
    path = resolve_scene_path(scene_ref)
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    if overrides:
        apply_overrides(data, overrides)
    table = dict(data.get("geometry", {}))
    name = table.get("builtin")
    if name not in builder_names():
        raise InputError("a closed form needs a built-in geometry", file=path, key="geometry.builtin", expected="one of " + ", ".join(builder_names()))
    params = dict(build_geometry(name, {k: v for k, v in table.items() if k not in ("builtin", "reference_point_mm", "spring_spacing_mm")}, file=str(path)).parameters)
    params["builtin"] = name
    return params


def _require(condition: bool, scene: Scene, problem: str, key: str, expected: str) -> None:
    if not condition:
        raise InputError(problem, file=scene.source, key=key, expected=expected)


def _check_builtin(scene: Scene, geometry: dict[str, Any], names: tuple[str, ...], form: str) -> None:
    _require(geometry["builtin"] in names, scene, f"the closed form '{form}' does not apply to geometry '{geometry['builtin']}'", "geometry.builtin", " or ".join(names))


def _check_threshold(scene: Scene, form: str) -> None:
    _require(scene.cartilage.law == "threshold", scene, f"the closed form '{form}' is for the threshold law", "cartilage.law", '"threshold"')
    _require(not scene.ligaments, scene, f"the closed form '{form}' has no ligaments", "ligaments", "no [[ligaments]]")
    _require(scene.kinematics is None, scene, f"the closed form '{form}' has a fixed tibia", "kinematics", "no [kinematics]")


def _check_fixed(scene: Scene, dofs: tuple[str, ...], form: str) -> None:
    missing = [d for d in dofs if d not in scene.fixed_dofs]
    _require(not missing, scene, f"the closed form '{form}' needs {', '.join(missing)} fixed", "constraints.fixed_dofs", "a list containing " + ", ".join(dofs))


def _normal_force(scene: Scene, form: str, *, monotonic: bool = False) -> np.ndarray:
    """The z component of the load per time point, checking the load is normal and compressive."""
    force = np.asarray(scene.load.force_n, dtype=np.float64)
    scale = max(float(np.abs(force).max(initial=0.0)), 1e-300)
    _require(bool(np.all(np.abs(force[:, :2]) <= 1e-12 * scale)), scene, f"the closed form '{form}' takes a normal load", "load.force_n", "[0, 0, F] at every time point")
    _require(bool(np.all(np.asarray(scene.load.moment_nmm) == 0.0)), scene, f"the closed form '{form}' takes no moment", "load.moment_nmm", "zero")
    fz = force[:, 2]
    _require(bool(np.all(fz >= 0.0)), scene, f"the closed form '{form}' needs a compressive load", "load.force_n", "F_z >= 0 (pushing the bodies together)")
    if monotonic:
        _require(bool(np.all(np.diff(fz) >= 0.0)), scene, f"the closed form '{form}' needs monotonic loading", "load.force_n", "a non-decreasing F_z")
    return fz


def _solution(name: str, formula: str, scene: Scene, **fields: Any) -> ClosedFormSolution:
    return ClosedFormSolution(name=name, formula=formula, time_s=np.asarray(scene.load.time_s, float), force_n=np.asarray(scene.load.force_n, float), **fields)


def _vertical(d_mm: np.ndarray) -> np.ndarray:
    out = np.zeros((d_mm.shape[0], 3))
    out[:, 2] = d_mm
    return out


# ---------------------------------------------------------------------------------------------
# The closed forms


def flat_plates(scene: Scene, geometry: dict[str, Any]) -> ClosedFormSolution:
    """Parallel plates (DEM, threshold law): p = F / A, d = F h / (E' A) at every time point."""
    form = "flat-plates"
    _check_builtin(scene, geometry, ("flat_plates",), form)
    _check_threshold(scene, form)
    _check_fixed(scene, ("tx", "ty"), form)
    h = float(geometry["gap_mm"])
    _require(h <= scene.cartilage.max_spring_length_mm, scene, "the plates are farther apart than h_max: no spring", "cartilage.max_spring_length_mm", f">= gap_mm ({h:g})")
    area = float(geometry["width_mm"]) * float(geometry["depth_mm"])
    e_conf = confined_modulus_mpa(scene.cartilage.youngs_modulus_mpa, scene.cartilage.poissons_ratio)
    fz = _normal_force(scene, form)
    loaded = fz > 0.0
    p = fz / area
    n_springs = scene.spring_area_mm2.shape[0]
    return _solution(
        form,
        "p = F / A, d = F h / (E' A)",
        scene,
        displacement_mm=_vertical(fz * h / (e_conf * area)),
        peak_pressure_mpa=p,
        mean_pressure_mpa=p,
        contact_area_mm2=np.where(loaded, area, 0.0),
        pressure_mpa=np.repeat(p[:, None], n_springs, axis=1),
        in_contact=np.repeat(loaded[:, None], n_springs, axis=1),
        spring_length_mm=np.full(n_springs, h),
        extra={"confined_modulus_mpa": e_conf, "plate_area_mm2": area, "gap_mm": h},
    )


def log_law(scene: Scene, geometry: dict[str, Any]) -> ClosedFormSolution:
    """EDEM on flat plates under monotonic loading: d = h0 (1 - exp(-F / (E' A))), p = F / A (docs/method.md#2-edem-the-time-dependent-incremental-method)."""
    form = "log-law"
    _check_builtin(scene, geometry, ("flat_plates",), form)
    _check_threshold(scene, form)
    _check_fixed(scene, ("tx", "ty"), form)
    h0 = float(geometry["gap_mm"])
    _require(h0 <= scene.cartilage.max_spring_length_mm, scene, "the plates are farther apart than h_max: no spring", "cartilage.max_spring_length_mm", f">= gap_mm ({h0:g})")
    area = float(geometry["width_mm"]) * float(geometry["depth_mm"])
    e_conf = confined_modulus_mpa(scene.cartilage.youngs_modulus_mpa, scene.cartilage.poissons_ratio)
    fz = _normal_force(scene, form, monotonic=True)
    loaded = fz > 0.0
    p = fz / area
    d = -h0 * np.expm1(-fz / (e_conf * area))
    n_springs = scene.spring_area_mm2.shape[0]
    return _solution(
        form,
        "d = h0 (1 - exp(-F / (E' A))), p = F / A",
        scene,
        displacement_mm=_vertical(d),
        peak_pressure_mpa=p,
        mean_pressure_mpa=p,
        contact_area_mm2=np.where(loaded, area, 0.0),
        pressure_mpa=np.repeat(p[:, None], n_springs, axis=1),
        in_contact=np.repeat(loaded[:, None], n_springs, axis=1),
        spring_length_mm=np.full(n_springs, h0),
        extra={"confined_modulus_mpa": e_conf, "plate_area_mm2": area, "gap_mm": h0, "final_strain": float(d[-1] / h0)},
    )


def log_law_edem_error(force_over_stiffness: float, n_increments: int, k: int | None = None) -> float:
    """Relative error of EDEM's displacement against the log law after k of n equal load increments.

    Each increment of the threshold law scales the remaining length by (1 - x / n) with
    x = F / (E' A) at the end of the ramp, so EDEM gives d_k = h0 (1 - (1 - x/n)^k) exactly;
    against h0 (1 - exp(-k x / n)) the error is first order in 1/n (about x / (2 n) after the
    first increment, x^2 e^-x / (2 n (1 - e^-x)) at the end). ``k`` defaults to n.
    """
    x, n = float(force_over_stiffness), int(n_increments)
    k = n if k is None else int(k)
    exact = -math.expm1(-k * x / n)
    return abs((1.0 - (1.0 - x / n) ** k) - exact) / exact


def log_law_edem_max_error(force_over_stiffness: float, n_increments: int) -> float:
    """The largest :func:`log_law_edem_error` over the n time points of the ramp (after 1..n increments)."""
    return max(log_law_edem_error(force_over_stiffness, n_increments, k) for k in range(1, int(n_increments) + 1))


def tilted_plane(scene: Scene, geometry: dict[str, Any]) -> ClosedFormSolution:
    """Plate under a tilted plane, rotations fixed: p(x) = E' d / h(x), h(x) = g + x tan(a)."""
    form = "tilted-plane"
    _check_builtin(scene, geometry, ("tilted_plane", "flat_plates"), form)
    _check_threshold(scene, form)
    _check_fixed(scene, ("tx", "ty", "rx", "ry", "rz"), form)
    g = float(geometry["gap_mm"])
    width, depth = float(geometry["width_mm"]), float(geometry["depth_mm"])
    slope = math.tan(math.radians(float(geometry.get("tilt_deg", 0.0))))
    h_max = scene.cartilage.max_spring_length_mm
    _require(g + abs(slope) * width / 2 <= h_max, scene, "part of the plate is farther than h_max from the plane", "cartilage.max_spring_length_mm", f">= {g + abs(slope) * width / 2:g} mm")
    e_conf = confined_modulus_mpa(scene.cartilage.youngs_modulus_mpa, scene.cartilage.poissons_ratio)
    # F = E' d D int_{-W/2}^{W/2} dx / (g + x tan a)
    if slope == 0.0:
        integral = depth * width / g
    else:
        integral = depth * math.log((g + slope * width / 2) / (g - slope * width / 2)) / slope
    fz = _normal_force(scene, form)
    d = fz / (e_conf * integral)
    h = g + scene.spring_centroid_mm[:, 0] * slope
    field_mpa = e_conf * d[:, None] / h[None, :]
    loaded = fz > 0.0
    area = width * depth
    return _solution(
        form,
        "p(x) = E' d / h(x), h(x) = g + x tan(a), F = E' d D ln(h(W/2) / h(-W/2)) / tan(a)",
        scene,
        displacement_mm=_vertical(d),
        peak_pressure_mpa=field_mpa.max(axis=1, initial=0.0),
        mean_pressure_mpa=fz / area,
        contact_area_mm2=np.where(loaded, area, 0.0),
        pressure_mpa=field_mpa,
        in_contact=np.repeat(loaded[:, None], h.shape[0], axis=1),
        spring_length_mm=h,
        extra={"confined_modulus_mpa": e_conf, "min_gap_mm": g - abs(slope) * width / 2, "max_gap_mm": g + abs(slope) * width / 2},
    )


def cylinder_plane(scene: Scene, geometry: dict[str, Any]) -> ClosedFormSolution:
    """Cylinder under a parallel plane (discrete elastic foundation): p = E' d cos(phi) / h(phi)."""
    from scipy.integrate import quad

    form = "cylinder-plane"
    _check_builtin(scene, geometry, ("ideal_ankle",), form)
    _require(not geometry["cartilage"], scene, f"the closed form '{form}' is for the cylinder under a plane, without cartilage", "geometry.cartilage", "false")
    _check_threshold(scene, form)
    _check_fixed(scene, ("tx", "ty", "rx", "ry", "rz"), form)
    _require(float(geometry.get("plafond_tilt_deg", 0.0)) == 0.0, scene, "the closed form 'cylinder-plane' needs a plane parallel to the axis", "geometry.plafond_tilt_deg", "0")
    r, width, g = float(geometry["radius_mm"]), float(geometry["width_mm"]), float(geometry["plafond_gap_mm"])
    half_arc = math.radians(float(geometry["arc_deg"])) / 2.0
    h_max = scene.cartilage.max_spring_length_mm
    _require(g < h_max, scene, "the plane is farther than h_max from the cylinder", "cartilage.max_spring_length_mm", f"> plafond_gap_mm ({g:g})")
    phi_c = min(math.acos((r + g) / (r + h_max)), half_arc)
    e_conf = confined_modulus_mpa(scene.cartilage.youngs_modulus_mpa, scene.cartilage.poissons_ratio)

    def length(phi: np.ndarray | float) -> np.ndarray | float:
        return (r + g) / np.cos(phi) - r

    vertical = quad(lambda f: math.cos(f) ** 2 / length(f), -phi_c, phi_c, epsabs=0.0, epsrel=1e-12)[0] * width * r
    normal = quad(lambda f: math.cos(f) / length(f), -phi_c, phi_c, epsabs=0.0, epsrel=1e-12)[0] * width * r
    fz = _normal_force(scene, form)
    d = fz / (e_conf * vertical)
    c = scene.spring_centroid_mm
    phi = np.arctan2(c[:, 1], c[:, 2] + r)
    inside = np.abs(phi) <= phi_c
    field_mpa = np.where(inside[None, :], e_conf * d[:, None] * np.cos(phi)[None, :] / length(phi)[None, :], 0.0)
    area = 2.0 * phi_c * r * width
    loaded = fz > 0.0
    return _solution(
        form,
        "p(phi) = E' d cos(phi) / h(phi), h(phi) = (R + g) / cos(phi) - R, F = E' d W R int cos^2(phi) / h dphi",
        scene,
        displacement_mm=_vertical(d),
        peak_pressure_mpa=field_mpa.max(axis=1, initial=0.0),
        mean_pressure_mpa=e_conf * d * normal / area,
        contact_area_mm2=np.where(loaded, area, 0.0),
        pressure_mpa=field_mpa,
        in_contact=inside[None, :] & loaded[:, None],
        spring_length_mm=np.where(np.abs(phi) <= half_arc, length(phi), np.inf),
        extra={
            "confined_modulus_mpa": e_conf,
            "contact_half_angle_deg": math.degrees(phi_c),
            "peak_pressure_at_top_mpa": float(e_conf * d[-1] / g),
        },
    )


def hemisphere_thickness(scene: Scene, geometry: dict[str, Any]) -> ClosedFormSolution:
    """Concentric hemispheres (thesis 4.2.2): every spring length is R_t - R.

    Also returns the faceting bound of the ray-cast lengths, computed from the scene's meshes:
    the largest depth of a target facet plane inside the target sphere plus the largest depth
    of a spring centroid inside the reference sphere. With rotations fixed and a load F along
    z, p(theta) = E' d cos(theta) / t with d = 3 F t / (2 pi R^2 E').
    """
    form = "hemisphere-thickness"
    _check_builtin(scene, geometry, ("hemispheres",), form)
    _check_threshold(scene, form)
    _check_fixed(scene, ("rx", "ry", "rz"), form)
    r, r_t = float(geometry["radius_mm"]), float(geometry["target_radius_mm"])
    t = r_t - r
    _require(t <= scene.cartilage.max_spring_length_mm, scene, "the target is farther than h_max", "cartilage.max_spring_length_mm", f">= {t:g}")
    centre = np.zeros(3)
    fixed = scene.fixed
    facet_distance = np.abs(np.einsum("ij,ij->i", fixed.unit_normals, fixed.vertices_mm[fixed.triangles[:, 0]] - centre))
    target_depth = float(r_t - facet_distance.min())
    c = scene.spring_centroid_mm - centre
    radius_c = np.linalg.norm(c, axis=1)
    mobile_depth = float(r - radius_c.min())
    e_conf = confined_modulus_mpa(scene.cartilage.youngs_modulus_mpa, scene.cartilage.poissons_ratio)
    fz = _normal_force(scene, form)
    d = 3.0 * fz * t / (2.0 * math.pi * r * r * e_conf)
    cos_theta = np.clip(c[:, 2] / radius_c, 0.0, 1.0)
    field_mpa = e_conf * d[:, None] * cos_theta[None, :] / t
    loaded = fz > 0.0
    area = 2.0 * math.pi * r * r
    return _solution(
        form,
        "h = R_t - R; p(theta) = E' d cos(theta) / t, d = 3 F t / (2 pi R^2 E')",
        scene,
        displacement_mm=_vertical(d),
        peak_pressure_mpa=e_conf * d / t,
        mean_pressure_mpa=e_conf * d / (2.0 * t),
        contact_area_mm2=np.where(loaded, area, 0.0),
        pressure_mpa=field_mpa,
        in_contact=np.repeat(loaded[:, None], c.shape[0], axis=1),
        spring_length_mm=np.full(c.shape[0], t),
        extra={"thickness_mm": t, "faceting_bound_mm": target_depth + mobile_depth, "target_facet_depth_mm": target_depth, "reference_centroid_depth_mm": mobile_depth},
    )


#: closed-form name -> function(scene, geometry parameters)
CLOSED_FORMS: dict[str, Callable[[Scene, dict[str, Any]], ClosedFormSolution]] = {
    "flat-plates": flat_plates,
    "tilted-plane": tilted_plane,
    "cylinder-plane": cylinder_plane,
    "log-law": log_law,
    "hemisphere-thickness": hemisphere_thickness,
}


def solve_closed_form(name: str, scene_ref: str | Path, overrides: dict[str, Any] | None = None) -> tuple[Scene, ClosedFormSolution]:
    """Load the scene (with overrides) and evaluate the named closed form on it."""
    if name not in CLOSED_FORMS:
        raise InputError(f"unknown closed form '{name}'", key="sides", expected="closed-form:" + " | closed-form:".join(CLOSED_FORMS))
    scene = load_scene(scene_ref, overrides or {})
    return scene, CLOSED_FORMS[name](scene, geometry_parameters(scene_ref, overrides))


def write_closed_form_results(scene: Scene, solution: ClosedFormSolution, out_dir: str | Path, wall_time_s: float = 0.0) -> Path:
    """The result directory (docs/result-format.md) of a closed form (method "closed-form:<name>").

    The pressure maps are the mobile surface translated by the closed-form displacement, with
    cell data pressure_mpa (the closed form at the spring centroids), spring_length_mm,
    in_contact and ray_hit, like `edem run`. summary.json adds "closed_form" (name, formula and
    the form's own numbers).
    """
    n_times = solution.time_s.shape[0]
    springs = scene.spring_triangle
    n_tri = scene.mobile.n_triangles
    summary = {
        "scene": scene.name,
        "method": f"closed-form:{solution.name}",
        "steps": n_times,
        "n_springs": int(springs.shape[0]),
        "wall_time_s": float(wall_time_s),
        "peak_pressure_mpa": float(solution.peak_pressure_mpa.max()),
        "max_contact_area_mm2": float(solution.contact_area_mm2.max()),
        "final_displacement_mm": [float(x) for x in solution.displacement_mm[-1]],
        "final_rotation_rad": [0.0, 0.0, 0.0],
        "max_force_residual_n": 0.0,
        "max_moment_residual_nmm": 0.0,
        "law": scene.cartilage.law,
        "warnings": [],
        "closed_form": {"name": solution.name, "formula": solution.formula, **solution.extra},
    }
    rows = [
        timeseries_row(k, solution.time_s[k], solution.force_n[k], solution.peak_pressure_mpa[k], solution.mean_pressure_mpa[k],
                       solution.contact_area_mm2[k], solution.displacement_mm[k], np.zeros(3), 0, 0.0)
        for k in range(n_times)
    ]
    length = np.zeros(n_tri)
    finite = np.isfinite(solution.spring_length_mm)
    length[springs] = np.where(finite, solution.spring_length_mm, 0.0)
    ray_hit = np.zeros(n_tri, np.int8)
    ray_hit[springs] = finite
    frames = []
    for k in range(n_times):
        pressure = np.zeros(n_tri)
        pressure[springs] = solution.pressure_mpa[k]
        contact = np.zeros(n_tri, np.int8)
        contact[springs] = solution.in_contact[k]
        cells = {"pressure_mpa": pressure, "spring_length_mm": length, "in_contact": contact, "ray_hit": ray_hit}
        surface = SurfaceFrame(scene.mobile.vertices_mm + solution.displacement_mm[k], scene.mobile.triangles, {}, cells)
        frames.append(Frame(k, float(solution.time_s[k]), surface))
    return write_result_dir(out_dir, summary, rows, frames, SurfaceFrame(scene.fixed.vertices_mm, scene.fixed.triangles))
