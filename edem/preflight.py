"""Geometry pre-flight (docs/method.md#9-geometry-pre-flight-and-spring-resolution): what the springs can
see before any solve, and whether the contact patch they resolve is fine enough after it.

:func:`preflight` measures, at the first loaded time point (M at its initial pose, F where that
time point puts it): the closest distance between the surfaces, the share of the spring-bearing
surface whose rays reach F within the window h_max, and the spring size against the contact patch
the load should make (a Winkler estimate). It refuses, before the solver would fail with a less
useful message, a scene whose springs in reach cannot hold the load (too few to restrain the free
DOFs, or on the wrong side to balance it) when springs further away could: the message gives the
gap in mm and the thickness or window to set. It also refuses a load that the constraints carry
entirely (the contact would see none of it). :func:`patch_resolution_warning` says, after the
solve, when the contact patch holds fewer than about :data:`PATCH_MIN_SPRINGS` springs.
"""

from __future__ import annotations

import collections
import hashlib
import math
from dataclasses import asdict, dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from geometries.errors import SolverError
from edem.mechanics import DOF_NAMES, balanceable, generalised_directions, unrestrained_dofs
from geometries.rowwise import add_rows, row_dot
from edem.springs import Placement, SpringGeometry, ligament_elements, spring_geometry
from geometries.surface import TriangleSurface
from geometries.triangle_kernels import closest_distance_mm

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from edem.raycast import RayCaster, Rays
    from edem.scene import Scene

#: Fewer springs than this in the contact patch resolve its pressure field poorly: of a patch's n
#: springs about 2 sqrt(pi n) sit on its rim, where the pressure drops to zero (25 of 50), and in
#: tests/edem/test_spring_resolution.py a patch of 56 springs leaves the peak 7.5 % and the area
#: 12 % off the closed form (200 springs: 1.7 % and 0.3 %).
PATCH_MIN_SPRINGS = 50
#: Springs nearest the closest point used to fit the gap's curvature (the fewest that still give
#: a curvature on a display mesh of a few hundred triangles).
CURVATURE_FIT_SPRINGS = 8
#: Closest distances kept per process (:func:`_closest_distance_of`), keyed by the surfaces' arrays:
#: a campaign's runs on one geometry (the sensitivity grid's 400 vary the cartilage and the
#: ligaments, not the bones) measure it once per worker instead of once per run (7 ms of its 110 ms).
CLOSEST_CACHE_SIZE = 4
_CLOSEST: collections.OrderedDict[bytes, float] = collections.OrderedDict()


def _closest_distance_of(mobile_vertices_mm: np.ndarray, mobile_triangles: np.ndarray, fixed_vertices_mm: np.ndarray,
                         fixed_triangles: np.ndarray) -> float:
    """closest_distance_mm between the two surfaces (mm), the last few kept: the key is a digest of
    the four arrays' dtypes, shapes and bytes, so only identical surfaces share a value."""
    digest = hashlib.blake2b(digest_size=20)
    for array in (mobile_vertices_mm, mobile_triangles, fixed_vertices_mm, fixed_triangles):
        array = np.ascontiguousarray(array)
        digest.update(f"{array.dtype.str}{array.shape}".encode())
        digest.update(array.data)
    key = digest.digest()
    if key in _CLOSEST:
        _CLOSEST.move_to_end(key)
        return _CLOSEST[key]
    _CLOSEST[key] = closest_distance_mm(mobile_vertices_mm, mobile_triangles, fixed_vertices_mm, fixed_triangles)[0]
    while len(_CLOSEST) > CLOSEST_CACHE_SIZE:
        _CLOSEST.popitem(last=False)
    return _CLOSEST[key]


@dataclass(frozen=True)
class Preflight:
    """What the springs see at the first loaded time point, before any solve (summary.json ``preflight``)."""

    time_point: int
    time_s: float
    closest_distance_mm: float  # between the surfaces (vertex to surface, both ways)
    shortest_ray_mm: float | None  # shortest signed spring ray that meets F (None: none does)
    window_mm: float  # h_max
    n_springs: int
    n_in_window: int  # springs whose ray meets F within the window (the candidates)
    share_in_window: float  # their share of the spring-bearing area
    spring_size_mm: float  # sqrt of the median spring area (springs facing F)
    median_edge_mm: float
    load_n: float  # |force| at this time point
    curvature_radius_mm: float | None  # relative radius of the gap at the closest point (None: conforming)
    patch_thickness_mm: float  # t of the Winkler estimate
    patch_radius_mm: float | None  # Winkler estimate of the contact patch's radius
    patch_springs: float | None  # springs of the median size in that patch

    def as_dict(self) -> dict:
        """JSON-ready (every number finite; None where not defined)."""
        return asdict(self)

    def lines(self) -> list[str]:
        """The pre-flight in a few lines, for the command line."""
        ray = "no spring's ray meets the fixed body" if self.shortest_ray_mm is None else f"{self.shortest_ray_mm:.3g} mm along the springs' normals"
        out = [
            f"pre-flight at time point {self.time_point} (t = {self.time_s:g} s; M at its initial pose, F at this time point's):",
            f"  closest distance between the surfaces {self.closest_distance_mm:.3g} mm ({ray})",
            f"  within the ray window h_max = {self.window_mm:g} mm: {self.n_in_window} of {self.n_springs} springs, "
            f"{100 * self.share_in_window:.3g} % of the spring-bearing area",
        ]
        size = f"  spring size {self.spring_size_mm:.3g} mm (sqrt of the median area; median edge {self.median_edge_mm:.3g} mm)"
        if self.patch_radius_mm is None:
            out.append(size + ("; conforming surfaces: no curvature-based patch estimate" if self.load_n else ""))
        else:
            out.append(
                size + f" against an expected contact patch of radius {self.patch_radius_mm:.3g} mm, about "
                f"{self.patch_springs:.0f} springs (Winkler: {self.load_n:.4g} N, t = {self.patch_thickness_mm:.3g} mm, "
                f"gap radius R = {self.curvature_radius_mm:.3g} mm)"
            )
        return out


def winkler_patch(load_n: float, modulus_mpa: float, thickness_mm: float, radius_mm: float) -> tuple[float, float, float]:
    """Approach d (mm), contact radius a (mm) and peak pressure p0 (MPa) of a rigid paraboloid of
    radius R pressed by F into a bed of independent springs p = E' delta / t (Winkler).

    The gap is r^2 / (2 R), so the bed is compressed by d - r^2 / (2 R) within a = sqrt(2 R d) and
    F = int_0^a E' / t (d - r^2 / (2 R)) 2 pi r dr = pi E' R d^2 / t: d = sqrt(F t / (pi E' R)),
    p0 = E' d / t.
    """
    approach = math.sqrt(load_n * thickness_mm / (math.pi * modulus_mpa * radius_mm))
    return approach, math.sqrt(2.0 * radius_mm * approach), modulus_mpa * approach / thickness_mm


def gap_curvature_radius_mm(length_mm: np.ndarray, centroid_mm: np.ndarray, normal: np.ndarray, fit_radius_mm: float = 0.0) -> float | None:
    """Relative radius R of the gap h(r) = h0 + r^2 / (2 R) around the spring with the shortest ray.

    ``length_mm`` (n,) are the springs' ray lengths (inf: no hit), ``centroid_mm`` (n, 3) and
    ``normal`` (n, 3) the springs. r is the distance from the closest spring across its normal;
    R is fitted by least squares over the springs within ``fit_radius_mm`` of it, and at least the
    :data:`CURVATURE_FIT_SPRINGS` nearest. None when the gap does not grow (conforming surfaces)
    or fewer than 3 springs see F.
    """
    profile = _gap_profile(length_mm, centroid_mm, normal)
    return None if profile is None else _fitted_radius_mm(profile, fit_radius_mm)


def _gap_profile(length_mm: np.ndarray, centroid_mm: np.ndarray, normal: np.ndarray) -> tuple[np.ndarray, np.ndarray, float] | None:
    """(r^2 (m,) mm^2, rise of the gap (m,) mm, r^2 of the CURVATURE_FIT_SPRINGS-th nearest) of the
    m springs that see F, about the closest one (:func:`gap_curvature_radius_mm`); None under 3."""
    hit = np.flatnonzero(np.isfinite(length_mm))
    if hit.size < 3:
        return None
    closest = hit[np.argmin(length_mm[hit])]
    offset = add_rows(np.take(centroid_mm, hit, axis=0), -centroid_mm[closest])
    across = row_dot(offset, offset) - (offset @ normal[closest]) ** 2
    rise = length_mm[hit] - length_mm[closest]
    nearest = min(CURVATURE_FIT_SPRINGS, hit.size - 1)
    return across, rise, float(np.partition(across, nearest)[nearest])


def _fitted_radius_mm(profile: tuple[np.ndarray, np.ndarray, float], fit_radius_mm: float) -> float | None:
    """R of the least-squares rise = r^2 / (2 R) over the springs of a :func:`_gap_profile` within
    ``fit_radius_mm`` (and at least its nearest few); None unless the gap grows."""
    across, rise, nearest = profile
    reach = max(nearest, fit_radius_mm**2)
    use = (across > 0) & (across <= reach)
    if use.sum() < 2:
        return None
    slope = float((across[use] * rise[use]).sum() / (across[use] ** 2).sum())  # rise = slope r^2
    return 0.5 / slope if slope > 0 else None


def _median_edge_mm(vertices_mm: np.ndarray, triangles: np.ndarray) -> float:
    """Median length (mm) of the edges of ``triangles`` (k, 3), each triangle's three counted.

    Corner by corner, as rows of points: a norm over a last axis of 3 runs several times slower
    (:mod:`geometries.rowwise`); the squares sum in the same order, so the lengths are the same numbers.
    """
    corners = [np.take(vertices_mm, triangles[:, j], axis=0) for j in range(3)]
    edges = [corners[j] - corners[j - 1] for j in range(3)]
    squared = np.concatenate([row_dot(e, e) for e in edges])
    # np.median's middle one or two, square-rooted after the partition (sqrt keeps the order)
    half = squared.size // 2
    middle = [half - 1, half] if squared.size % 2 == 0 else [half]
    return float(np.sqrt(np.partition(squared, middle)[middle]).mean())


def _rows(centroid_mm: np.ndarray, normal: np.ndarray, area_mm2: np.ndarray, reference_mm: np.ndarray, shear: bool) -> tuple[np.ndarray, np.ndarray]:
    """Generalised directions (m, 6) of springs and their weights (their areas): the normal rows,
    and with shear stiffness the rows along +-x, +-y, +-z as well (a shear spring pushes both ways)."""
    rows = [generalised_directions(centroid_mm, normal, reference_mm)]
    weights = [area_mm2]
    if shear:
        for axis in np.vstack([np.eye(3), -np.eye(3)]):
            rows.append(generalised_directions(centroid_mm, np.broadcast_to(axis, centroid_mm.shape), reference_mm))
            weights.append(area_mm2)
    return np.vstack(rows), np.concatenate(weights)


def _shortfall(rows: np.ndarray, weights: np.ndarray, load: np.ndarray, free: np.ndarray, length_scale_mm: float) -> str | None:
    """What the elements (rows, compression or tension only) cannot do for the load on the free
    DOFs: 'restrain <dofs>' or 'balance the load', or None when they can do both."""
    stiffness = rows.T @ (rows * weights[:, None])
    missing = unrestrained_dofs(stiffness, free, length_scale_mm)
    if missing:
        return f"restrain {', '.join(missing)}"
    to_newton = np.array([1.0, 1.0, 1.0] + [1.0 / length_scale_mm] * 3)
    if not balanceable(rows, load, free, to_newton):
        return "balance the load (they all lie on one side of its line of action, or it pulls the bodies apart)"
    return None


def _two_digits(x: float, up: bool = True) -> float:
    """x rounded up (or down) to two significant digits (a value to type into a scene file)."""
    if x <= 0:
        return 0.0
    step = 10.0 ** (math.floor(math.log10(x)) - 1)
    return round((math.ceil(x / step - 1e-9) if up else math.floor(x / step + 1e-9)) * step, 12)


def preflight(
    scene: Scene,
    loads: np.ndarray,
    fixed_pose: Callable[[int], Placement],
    caster: RayCaster,
    rays: Rays,
    first_geometry: SpringGeometry | None = None,
) -> Preflight:
    """Measure what the springs see at the first loaded time point, and refuse what cannot be solved.

    Parameters
    ----------
    scene : Scene
        The scene (its springs, cartilage, constraints and ligaments).
    loads : (n_times, 6) float
        Force (N) and moment about G (N mm) per time point, global axes (as the solver applies them).
    fixed_pose : callable
        Time point index -> F's placement.
    caster, rays : RayCaster, Rays
        The fixed body's ray caster and M's springs prepared for it (as the solver uses them).
    first_geometry : SpringGeometry, optional
        M's springs already measured at its initial pose against F at time point 0 (the solver's
        first step): used, not measured again, when time point 0 is the one checked.

    Returns
    -------
    Preflight

    Raises
    ------
    SolverError
        When the constraints carry the whole load at every loaded time point; or when the springs
        within the window cannot restrain the free DOFs or balance the load at the first loaded
        time point (or none is in reach) while springs further out could: with the gap in mm and
        the thickness or window to set.
    """
    cartilage = scene.cartilage
    free = np.array([d not in scene.fixed_dofs for d in DOF_NAMES])
    magnitude = np.abs(loads).max(axis=1)
    loaded = np.flatnonzero(magnitude > 0)
    carried = np.abs(loads[:, free]).max(axis=1, initial=0.0) <= 1e-12 * magnitude
    if loaded.size and np.all(carried[loaded]):
        k = int(loaded[np.argmax(magnitude[loaded])])
        along = [DOF_NAMES[i] for i in np.flatnonzero(np.abs(loads[k]) > 1e-12 * magnitude[k])]
        raise SolverError(
            f"the applied load lies entirely along [constraints] fixed_dofs = {list(scene.fixed_dofs)} (e.g. "
            f"{np.linalg.norm(loads[k, :3]):.4g} N, {np.linalg.norm(loads[k, 3:]):.4g} N mm at t = {scene.load.time_s[k]:g} s, "
            f"along {', '.join(along)}): the constraints carry all of it and the contact sees none; free the DOFs the load "
            "presses along, or give a zero load to see the pose's pressures alone"
        )
    k = int(loaded[0]) if loaded.size else 0
    t = float(scene.load.time_s[k])
    g0 = scene.reference_point_mm
    mobile_pose, f_pose = Placement.identity(g0), fixed_pose(k)
    centroid, normal, area = scene.spring_centroid_mm, scene.spring_normal, scene.spring_area_mm2
    # M's reference frame: F's vertices placed there (M is at its initial pose).
    placed = TriangleSurface(f_pose.points(scene.fixed.vertices_mm), scene.fixed.triangles)
    closest = _closest_distance_of(scene.mobile.vertices_mm, scene.mobile.triangles, placed.vertices_mm, placed.triangles)
    if k == 0 and first_geometry is not None:
        in_window = first_geometry
    else:
        in_window = spring_geometry(centroid, normal, area, mobile_pose, caster, f_pose, cartilage, rays)
    # Rays across the whole scene ahead of the springs (from -h_max, as the window, to the far
    # side of both bodies): the gap field, and the springs that face F at any distance. The
    # caster's window is symmetric: the rays start half the span ahead, and their lengths are
    # measured back from the springs.
    # (column by column: numpy's reductions over the rows of an (n, 3) array run ~20x slower)
    bodies = (scene.mobile.vertices_mm, placed.vertices_mm)
    diagonal = np.array([max(b[:, j].max() for b in bodies) - min(b[:, j].min() for b in bodies) for j in range(3)])
    half = 0.5 * (cartilage.max_spring_length_mm + float(np.linalg.norm(diagonal)))
    ahead = half - cartilage.max_spring_length_mm
    shifted = caster.prepare(centroid + ahead * normal, normal)
    wide = spring_geometry(centroid, normal, area, mobile_pose, caster, f_pose, replace(cartilage, max_spring_length_mm=half), shifted)
    length = wide.spring_length_mm + ahead
    facing = np.isfinite(length)
    sizes = area[facing] if facing.any() else area
    tri = scene.mobile.triangles[scene.spring_triangle[facing] if facing.any() else scene.spring_triangle]
    median_edge = _median_edge_mm(scene.mobile.vertices_mm, tri)
    spring_size = math.sqrt(float(np.median(sizes)))

    load_n = float(np.linalg.norm(loads[k, :3]))
    if not cartilage.spring_law.needs_thickness:
        patch_t = cartilage.max_spring_length_mm
    elif cartilage.layers is not None:  # measured layers in series: their typical total thickness
        patch_t = float(np.median(cartilage.layers.mobile.thickness_mm) + np.median(cartilage.layers.fixed.thickness_mm))
    else:
        patch_t = cartilage.thickness_mm
    profile = _gap_profile(length, centroid, normal)
    radius = None if profile is None else _fitted_radius_mm(profile, 0.0)
    patch = None
    if radius is not None and load_n > 0:
        _, a, _ = winkler_patch(load_n, cartilage.confined_modulus_mpa, patch_t, radius)
        radius = _fitted_radius_mm(profile, 2.0 * a)  # refit over the patch
        if radius is not None:
            patch = winkler_patch(load_n, cartilage.confined_modulus_mpa, patch_t, radius)[1]
    report = Preflight(
        time_point=k,
        time_s=t,
        closest_distance_mm=closest,
        shortest_ray_mm=float(length[facing].min()) if facing.any() else None,
        window_mm=float(cartilage.max_spring_length_mm),
        n_springs=int(area.size),
        n_in_window=int(in_window.candidate_index.size),
        share_in_window=float(area[in_window.candidate].sum() / area.sum()),
        spring_size_mm=spring_size,
        median_edge_mm=median_edge,
        load_n=load_n,
        curvature_radius_mm=radius,
        patch_thickness_mm=float(patch_t),
        patch_radius_mm=patch,
        patch_springs=None if patch is None else math.pi * patch**2 / spring_size**2,
    )
    if loaded.size:
        _refuse_out_of_reach(scene, report, loads[k], free, in_window.candidate, length, f_pose)
    return report


def _refuse_out_of_reach(
    scene: Scene, report: Preflight, load: np.ndarray, free: np.ndarray, in_reach: np.ndarray, length_mm: np.ndarray, f_pose: Placement
) -> None:
    """SolverError with the gap and what to set when the springs in reach cannot hold the load."""
    g0 = scene.reference_point_mm
    centroid, normal, area = scene.spring_centroid_mm, scene.spring_normal, scene.spring_area_mm2
    shear = scene.cartilage.shear_modulus_mpa > 0
    lig_rows, lig_law, _ = ligament_elements(scene.ligaments, Placement.identity(g0), f_pose, g0)
    arm = add_rows(centroid, -g0)
    length_scale = float(np.sqrt(row_dot(arm, arm).mean()))

    def shortfall(springs: np.ndarray) -> str | None:
        """(springs: indices; row gathers by take, a boolean mask over (n, 3) rows is slower)"""
        rows, weights = _rows(np.take(centroid, springs, axis=0), np.take(normal, springs, axis=0), np.take(area, springs), g0, shear)
        return _shortfall(np.vstack([rows, lig_rows]), np.concatenate([weights, lig_law.stiffness_n_per_mm]), load, free, length_scale)

    problem = shortfall(np.flatnonzero(in_reach))
    if problem is None:
        return
    # The smallest window whose springs would do it (a larger window only adds springs).
    order = np.argsort(length_mm)
    order = order[np.isfinite(length_mm[order])]
    enough = None
    if order.size and shortfall(order) is None:
        low, high = 0, order.size - 1
        while low < high:
            mid = (low + high) // 2
            if shortfall(order[: mid + 1]) is None:
                high = mid
            else:
                low = mid + 1
        needed = _two_digits(max(float(length_mm[order[low]]), 0.0) * 1.05)  # (5 % beyond the last spring it needs)
        enough = (needed, int(np.count_nonzero(length_mm <= needed)))
    if enough is None and report.n_in_window:
        return  # not a matter of reach: the solver says why (constraints, load direction)
    window, law = report.window_mm, scene.cartilage.law
    gap = f"the surfaces are {report.closest_distance_mm:.3g} mm apart at their closest"
    if report.shortest_ray_mm is not None:
        gap += f" ({report.shortest_ray_mm:.3g} mm along the springs' normals)"
    where = f"time point {report.time_point} (t = {report.time_s:g} s)"
    if report.n_in_window:
        reach = (f"{report.n_in_window} of {report.n_springs} springs ({100 * report.share_in_window:.2g} % of the spring-bearing area) "
                 f"reach the fixed body within the ray window max_spring_length_mm = {window:g} mm, too few to {problem}")
    else:
        reach = f"no spring is a candidate: none of the {report.n_springs} springs reaches the fixed body within the ray window max_spring_length_mm = {window:g} mm"
    head = f"{where}: {reach}; {gap}"
    if enough is None:
        raise SolverError(
            f"{head}. No spring of the mobile body would hold this load at any reach: check the load's direction and sign, "
            "the bodies (mobile_body, fixed_body) and the pose"
        )
    new_window, n_springs = enough
    thickness = _two_digits(report.shortest_ray_mm) if report.shortest_ray_mm and report.shortest_ray_mm > 0 else None
    advice = (
        f". A window of {new_window:g} mm would reach {n_springs} springs, enough to hold it. Bone or display meshes "
        "without cartilage? The gap is the joint space the cartilage fills: set [cartilage] law = \"gap\""
        + (f" with thickness_mm = {thickness:g} (the gap along the springs)" if thickness else "")
        + f" and max_spring_length_mm = {max(new_window, thickness or 0.0):g}"
        + (" (the threshold law's area is set by the window, not by the load)" if law == "threshold" else "")
        + ", with [geometry] spring_spacing_mm to put enough springs in the contact patch"
        + f". Articular (cartilage) surfaces already? Set max_spring_length_mm = {new_window:g}, or check the pose that puts them apart"
    )
    raise SolverError(head + advice)


def patch_resolution_warning(steps: Sequence, minimum: int = PATCH_MIN_SPRINGS) -> list[str]:
    """Say so when a loaded time point's contact patch holds fewer than ``minimum`` springs.

    ``steps`` are the solver's StepResults (``in_contact``, ``area_mm2``, ``force_n``,
    ``moment_nmm``). The warning names the fewest springs, where, and a spacing that puts about
    ``minimum`` springs or more in that patch.
    """
    counts = []
    for s in steps:
        n = int(np.count_nonzero(s.in_contact))
        if n and (np.any(s.force_n) or np.any(s.moment_nmm)):
            counts.append((n, s))
    few = [(n, s) for n, s in counts if n < minimum]
    if not few:
        return []
    n, s = min(few, key=lambda item: item[0])
    area = float(s.area_mm2[s.in_contact].sum())
    others = f" (and {len(few) - 1} more of the {len(counts)} loaded time points hold fewer than {minimum})" if len(few) > 1 else ""
    return [
        f"the contact patch holds only {n} springs at time point {s.step} (t = {s.time_s:g} s, {area:.3g} mm^2){others}: "
        f"fewer than about {minimum} springs do not resolve its pressure (peak and area change with the mesh); resample "
        f"the spring-bearing surface with [geometry] spring_spacing_mm = {_two_digits(math.sqrt(area / minimum), up=False):g} or finer"
    ]
