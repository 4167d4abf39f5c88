"""DEM and EDEM over a load history (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs, docs/method.md#2-edem-the-time-dependent-incremental-method): the time loop around the static solve."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from edem.beds import ContactStep, scene_bed
from edem.consistency import DEM_IMBALANCE_FRACTION, check_contact_kept, check_increment, remeasured_warning
from geometries.errors import InputError, SolverError
from edem.laws import stack_elements
from edem.mechanics import DOF_NAMES, generalised_directions, rotation_matrix, rotation_vector, turn_rows
from edem.plausibility import emit, merge_repeated
from edem.preflight import patch_resolution_warning, preflight
from edem.raycast import RayCaster
from edem.results import RunResult, StepResult
from geometries.rowwise import add_rows, row_dot
from edem.scene import Scene
from edem.springs import Cartilage, Placement, SpringGeometry, contact_law, ligament_elements, ligament_table, shear_terms, spring_geometry
from edem.viscoelastic import viscoelastic_stepping


#: the discrete methods: DEM (static, from M's initial pose at every time point) and EDEM (docs/method.md#2-edem-the-time-dependent-incremental-method)
METHODS = ("edem", "dem")


#: a gap-law spring overlapping by less than this share of its thickness touches rather than
#: starts compressed: its preload, p = 0.01 E' (0.26 MPa on the ankles' cartilage), is well below
#: the pressures a load makes. The built-in ankles' articular surfaces, placed touching at the
#: neutral pose, overlap by up to 0.02 mm (0.7 % of T) at the stance's first ankle angle, -3 deg:
#: the subject-like trochlea is wider anteriorly, so the mortise tightens as the tibia turns
TOUCHING_OVERLAP = 1e-2


def precompression_warning(geometry: SpringGeometry, cartilage: Cartilage) -> list[str]:
    """Say so when a gap-law bed starts compressed (t larger than the gap h, beyond
    :data:`TOUCHING_OVERLAP`): it pushes the bodies apart before any load, so the first time
    point's result includes that preload."""
    t = geometry.candidate_thickness_mm(cartilage)  # (measured thickness: one per candidate)
    if t is None or not cartilage.spring_law.needs_thickness:
        return []
    h = geometry.candidate_length_mm
    compressed = h < t * (1.0 - TOUCHING_OVERLAP)
    if not np.any(compressed):
        return []
    thickness = f"thickness t = {float(t):g} mm" if np.ndim(t) == 0 else "local total thickness t_M + t_F"
    return [
        f"the {cartilage.law} bed starts pre-compressed: {int(compressed.sum())} springs are shorter than the "
        f"{thickness}, by up to {float((t - h).max()):.3g} mm (the gap between the surfaces is less "
        "than t): the bodies push apart before any load; check the thickness against the gap"
    ]


def compression_ratio(geometry: SpringGeometry, cartilage: Cartilage, approach_mm: np.ndarray) -> np.ndarray:
    """Compression over undeformed length of the candidate springs after an approach (strain)."""
    return cartilage.spring_law.strain(geometry.candidate_length_mm, approach_mm, geometry.candidate_thickness_mm(cartilage))


def _index_runs(indices: list[int]) -> str:
    """'1-20, 22, 24-47': consecutive time point indices as runs."""
    runs: list[list[int]] = []
    for k in indices:
        if runs and k == runs[-1][1] + 1:
            runs[-1][1] = k
        else:
            runs.append([k, k])
    return ", ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in runs)


def bone_overlap_message(overlaps: list[tuple[int, float, int, float]], n_times: int, method: str) -> str:
    """Why a result whose springs are compressed past their length is refused: the time points
    (index runs and times), the springs and their share of those in contact, the worst time point
    (``overlaps``: (k, t, springs, share) per time point), and what to do."""
    k, t, count, share = (list(x) for x in zip(*overlaps))
    worst = max(overlaps, key=lambda item: item[3])

    def span(values: list, fmt: str) -> str:
        low, high = min(values), max(values)
        return format(low, fmt) if low == high else f"{format(low, fmt)}-{format(high, fmt)}"

    return (
        f"springs are compressed past their length (strain >= 100 %: the bone-to-bone length is below 0, the bones pass "
        f"through each other) at {len(k)} of {n_times} time points (k = {_index_runs(k)}; t = {span(t, 'g')} s): "
        f"{span(count, 'd')} springs, {span([100 * x for x in share], '.3g')} % of those in contact (worst: k = {worst[0]}, "
        f"t = {worst[1]:g} s, {worst[2]} springs, {100 * worst[3]:.3g} %). The spring bed cannot represent that contact: "
        "give the bodies their cartilage (bone meshes under articular surfaces, or a thickness that matches the gap), "
        "a load in the joint's range"
        + (", or more time points ([load] max_step_s)" if method == "edem" else "")
        + "; [solver] allow_bone_overlap = true keeps such a result (stability studies)"
    )


def constrained_moment_warning(loads: np.ndarray, fixed_dofs: tuple[str, ...]) -> list[str]:
    """Say so when the applied moment about G has components along fixed rotations: the
    constraint carries them and the spring bed never sees them (never dropped silently)."""
    fixed = [i for i, name in enumerate(DOF_NAMES[3:]) if name in fixed_dofs]
    if not fixed:
        return []
    largest = np.abs(loads[:, 3:][:, fixed]).max(axis=0)
    scale = max(float(np.abs(loads[:, 3:]).max()), 1e-300)
    carried = [f"{DOF_NAMES[3 + i]} (up to {m:.4g} N mm)" for i, m in zip(fixed, largest) if m > 1e-9 * scale]
    if not carried:
        return []
    return [
        f"the applied moment about G has components about {', '.join(carried)}, which [constraints] fixed_dofs "
        "carry: the contact does not see them (free these rotations, or move G, e.g. to the joint centre, "
        "if the contact should carry them)"
    ]


def run(
    scene: Scene,
    method: str | None = None,
    *,
    caster: RayCaster | None = None,
    progress: Callable[[int], None] | None = None,
) -> RunResult:
    """Solve every time point of the scene with DEM (static, from M's initial pose) or EDEM.

    EDEM (docs/method.md#2-edem-the-time-dependent-incremental-method): at each step the geometry is redone at M's accumulated pose and F's pose for
    that time, the stored spring forces of the springs still in contact push back (eq. 3.17),
    the increment solves K u = T_k - p with the active set handled as in DEM (eq. 3.18-3.19),
    then the forces are committed and M is moved by u. Springs that left contact keep no force.
    The scene's bed (:mod:`edem.beds`, ``cartilage.coupling``) does each solve, its viscoelastic
    increment, its warnings and DEM's re-measure; the committed forces are its pressure field.
    """
    method = method or scene.method
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}", key="method", expected=" or ".join(METHODS))
    started = time.perf_counter()
    caster = caster or RayCaster(scene.fixed.vertices_mm, scene.fixed.triangles)
    cartilage = scene.cartilage
    g0 = scene.reference_point_mm
    n_springs = scene.spring_area_mm2.shape[0]
    spring_centroid, spring_normal, spring_area = scene.spring_centroid_mm, scene.spring_normal, scene.spring_area_mm2
    arm = add_rows(spring_centroid, -g0)
    arm_squared = row_dot(arm, arm)
    length_scale = float(np.sqrt(arm_squared.mean()))
    # Distance of the furthest spring from G: no rigid motion of M changes it (check_increment's bound).
    arm_bound = float(np.sqrt(arm_squared.max(initial=0.0)))
    load = scene.load
    loads = scene.applied_loads()
    warnings: list[str] = constrained_moment_warning(loads, scene.fixed_dofs)
    # the Kelvin-Voigt springs' time steps (edem.viscoelastic: the contact set frozen as in the thesis, or creeping)
    viscous = viscoelastic_stepping(scene, loads) if method == "edem" and scene.viscoelastic is not None else None
    if scene.viscoelastic is not None and viscous is None:
        warnings.append("[viscoelastic] is ignored by DEM, a static method: use --method edem")
    if viscous is not None:
        warnings += viscous.warnings
    # Committed (elastic) spring forces, the EDEM push-back, one row per axis (3, n): gathers and
    # scatters of the candidates' columns run along contiguous rows (several times cheaper than
    # over (n, 3) rows).
    stored = np.zeros((3, n_springs))
    pose = Placement.identity(g0)
    bed = scene_bed(scene, caster)
    steps: list[StepResult] = []
    unbalanced: list[tuple[int, float]] = []  # DEM time points whose re-measured springs miss the load
    overlaps: list[tuple[int, float, int, float]] = []  # time points whose springs pass their length: (k, t, springs, share in contact)
    free = np.array([d not in scene.fixed_dofs for d in DOF_NAMES])
    ligaments = ligament_table(scene.ligaments)
    reference_rows = generalised_directions(spring_centroid, spring_normal, g0)
    rays = caster.prepare(spring_centroid, spring_normal)  # checked once, cast at every time point
    # M's springs at its initial pose at time point 0: the first step's geometry, which the
    # pre-flight also checks when the load starts at time point 0 (measured once for both).
    clock = time.perf_counter()
    first_geometry = spring_geometry(spring_centroid, spring_normal, spring_area, pose, caster, scene.fixed_placement(0), cartilage, rays)
    first_geometry_s = time.perf_counter() - clock  # the first step's, counted in the solve
    report = preflight(scene, loads, scene.fixed_placement, caster, rays, first_geometry)
    # Set-up (the caster's scene, the bed, the pre-flight, lazy imports: paid once per run, most
    # of it once per process) is timed apart from the solve of the time points.
    solve_started = time.perf_counter()
    setup_s = solve_started - started - first_geometry_s
    seconds = {"geometry": first_geometry_s, "solve": 0.0}
    for k, t in enumerate(load.time_s):
        clock = time.perf_counter()
        if method == "dem":
            pose, stored = Placement.identity(g0), np.zeros((3, n_springs))
        f_pose = scene.fixed_placement(k)
        geometry = first_geometry if k == 0 else spring_geometry(spring_centroid, spring_normal, spring_area, pose, caster, f_pose, cartilage, rays)
        seconds["geometry"] += time.perf_counter() - clock
        clock = time.perf_counter()
        n_c = int(geometry.candidate_index.size)
        if cartilage.spring_law.needs_positive_length and (geometry.candidate_length_mm <= 0.0).any():
            # k = E'/h (threshold) and p = -E' ln(h/t) (gap-log) have no meaning once h <= 0.
            bad = int((geometry.candidate_length_mm <= 0.0).sum())
            raise SolverError(
                f"time point {k} (t = {t:g} s): {bad} springs are compressed past their length "
                f"(h <= 0, the bodies interpenetrate); the {cartilage.law} law needs h > 0: "
                + ("use more time points so each increment is small ([load] max_step_s), or the linear gap law" if k else "separate the bodies or use the linear gap law")
            )
        if n_c == 0 and not scene.ligaments and np.any(loads[k]):
            raise SolverError(
                f"time point {k} (t = {t:g} s): no spring is a candidate: no part of the fixed body lies "
                f"within h_max = {cartilage.max_spring_length_mm:g} mm of the mobile body along its normals"
            )
        g_current = g0 + pose.translation_mm  # (G is M's pivot: R (G - G) + G + t)
        # Gather the candidates once by index (cheaper than repeated boolean masks over all springs).
        cand_idx = geometry.candidate_index
        lig_rows, lig_law, _ = ligament_elements(ligaments, pose, f_pose, g_current)
        # Rows g = (n, (c - G) x n) of the candidates: both parts turn with M, so they are the
        # reference rows (built once) turned by M's rotation; one gather and one product.
        directions = turn_rows(reference_rows.take(cand_idx, axis=0), pose.rotation, len(lig_rows))
        directions[n_c:] = lig_rows
        normals = directions[:n_c, :3]
        area_c = geometry.candidate_area_mm2
        stored_c = stored.take(cand_idx, axis=1).T
        stored_normal = row_dot(stored_c, normals)
        # (the tangential part of the stored forces only matters, and is only formed, with shear)
        shear = shear_terms(geometry, cartilage, g_current, stored_c - stored_normal[:, None] * normals) if cartilage.shear_modulus_mpa else None
        law = stack_elements(contact_law(geometry, cartilage, stored_normal), lig_law)
        contact_step = ContactStep(geometry, directions, law, stored_normal, lig_rows, lig_law, shear, scene.fixed_dofs, length_scale)
        try:
            if viscous is None:
                solution = bed.solve(contact_step, loads[k])
            else:
                contact_step = viscous.prepare(k, contact_step)
                solution = viscous.solve(bed, contact_step, loads[k])
        except SolverError as exc:
            cause = (
                f" (no spring is a candidate here: no part of the fixed body lies within h_max = "
                f"{cartilage.max_spring_length_mm:g} mm of the mobile body along its normals, so only the ligaments resist)"
                if n_c == 0 else ""
            )
            raise SolverError(f"time point {k} (t = {t:g} s, {n_c} candidate springs): {exc}{cause}") from None
        total_force = np.where(solution.active, solution.element_force_n, 0.0)
        where = f"time point {k} (t = {t:g} s)"
        warnings += bed.step_warnings(contact_step, solution, where)
        if k == 0:
            warnings += precompression_warning(geometry, cartilage)
            warnings += bed.first_step_warnings(contact_step, solution)
        overstrained = int((solution.active[:n_c] & (compression_ratio(geometry, cartilage, directions[:n_c] @ solution.displacement) >= 1.0)).sum())
        if overstrained:
            in_contact_now = max(int(solution.active[:n_c].sum()), 1)
            overlaps.append((k, float(t), overstrained, overstrained / in_contact_now))
            if scene.allow_bone_overlap:
                warnings.append(
                    f"time point {k} (t = {t:g} s): {overstrained} springs compressed past their length "
                    "(strain >= 100 %): the spring bed is outside its range" + (", use more time points ([load] max_step_s)" if method == "edem" else "")
                )
        if viscous is None:
            u, elastic_force = solution.displacement, total_force
        else:
            u, elastic_force = viscous.increment(bed, contact_step, solution, k, loads)
            if not np.all(np.isfinite(u)):
                raise SolverError(f"time point {k} (t = {t:g} s): the viscoelastic integration diverged (non-finite displacement)")
        # Overflowed numbers pass every comparison below (NaN > limit is False): refuse them here.
        # (A finite sum has no inf or nan term; a sum that overflowed takes the exact test.)
        if not math.isfinite(float(u.sum()) + float(elastic_force.sum())) and not (np.all(np.isfinite(u)) and np.all(np.isfinite(elastic_force))):
            raise SolverError(
                f"time point {k} (t = {t:g} s): the solution diverged (non-finite displacement or spring forces; "
                f"load {np.abs(loads[k]).max():.3g} against {n_c} springs of modulus {cartilage.youngs_modulus_mpa:g} MPa): "
                "check the load's units and scale and the cartilage modulus"
            )
        contact = directions[:n_c].T @ total_force[:n_c]
        if shear is not None:  # (the step's: a creeping step's shear springs carry their dashpots' share too)
            contact = contact + contact_step.shear.generalised_force(solution.displacement, solution.active[:n_c])
        spring_force = total_force[:n_c]
        # sum f (R X + b) / sum f = R (sum f X / sum f) + b: the candidates' centroids are only
        # placed at the pose if check_increment needs them.
        force_sum = spring_force.sum()
        centre = pose.points((spring_force @ spring_centroid.take(cand_idx, axis=0))[None] / force_sum)[0] if force_sum > 0 else g_current
        if not solution.active[:n_c].any():  # (M's normals at the pose are only formed for this check)
            check_contact_kept(loads[k, :3], geometry.normal, spring_area, 0, free, u, where)
        check_increment(
            u, lambda: geometry.candidate_centroid_mm, g_current, cartilage, where, arm_bound_mm=arm_bound, in_contact=solution.active[:n_c]
        )
        # (3, c) in C order: a product laid out like the transposed view would be several times slower
        committed = np.multiply(normals.T, elastic_force[:n_c], order="C")
        if shear is not None:
            committed += shear.force(u, solution.active[:n_c]).T
        stored = np.zeros((3, n_springs))
        for axis in range(3):  # one contiguous scatter per axis: twice as fast as one 2-D scatter
            stored[axis, cand_idx] = committed[axis]
        in_contact = np.zeros(n_springs, bool)
        in_contact[cand_idx] = solution.active[:n_c]
        if viscous is not None:
            stored = viscous.commit(stored, in_contact)
        pose = Placement(rotation_matrix(u[3:]) @ pose.rotation, pose.translation_mm + u[:3], g0)
        remeasured = None
        if method == "dem":
            clock_remeasure = time.perf_counter()
            remeasured = bed.remeasured_imbalance(contact_step, solution, u, pose, f_pose, loads[k])
            seconds["geometry"] += time.perf_counter() - clock_remeasure
            clock += time.perf_counter() - clock_remeasure  # counted as geometry, not as solve
            if remeasured is not None and remeasured > DEM_IMBALANCE_FRACTION:
                unbalanced.append((k, remeasured))
        pressure = np.zeros(n_springs)
        pressure[cand_idx] = total_force[:n_c] / area_c
        viscous_pressure = np.zeros(n_springs)
        if viscous is not None:
            viscous_pressure[cand_idx] = (total_force[:n_c] - elastic_force[:n_c]) / area_c
        seconds["solve"] += time.perf_counter() - clock
        steps.append(
            StepResult(
                step=k,
                time_s=float(t),
                force_n=loads[k, :3].copy(),
                moment_nmm=loads[k, 3:].copy(),
                displacement_mm=pose.translation_mm.copy(),
                rotation_rad=rotation_vector(pose.rotation),
                pressure_mpa=pressure,
                viscous_pressure_mpa=viscous_pressure,
                spring_length_mm=geometry.spring_length_mm,
                in_contact=in_contact,
                ligament_force_n=total_force[n_c:],
                iterations=solution.iterations,
                force_residual_n=solution.force_residual_n,
                moment_residual_nmm=solution.moment_residual_nmm,
                mobile_placement=pose,
                fixed_placement=f_pose,
                area_mm2=spring_area,
                remeasured_imbalance=remeasured,
                contact_force_n=contact[:3],
                contact_moment_nmm=contact[3:],
                centre_of_pressure_mm=centre,
            )
        )
        if progress is not None:
            progress(k)
    if overlaps and not scene.allow_bone_overlap:
        raise SolverError(bone_overlap_message(overlaps, len(load.time_s), method))
    if unbalanced:
        worst = max(unbalanced, key=lambda item: item[1])
        warnings.append(remeasured_warning(len(unbalanced), worst[0], worst[1]))
    warnings += patch_resolution_warning(steps)
    return RunResult(scene, method, steps, time.perf_counter() - solve_started + first_geometry_s, merge_repeated(warnings), seconds, report,
                     setup_time_s=setup_s)


def solve(scene: Scene, method: str | None = None, *, progress: Callable[[int], None] | None = None) -> RunResult:
    """Solve every time point of a scene with the discrete method.

    Parameters
    ----------
    scene : Scene
        From :func:`edem.scene.load_scene` or :meth:`edem.scene.Scene.from_arrays`.
    method : {"edem", "dem"}, optional
        EDEM (incremental, with the push-back of the springs' stored forces) or DEM (static at
        every time point); default the scene's ``method``.
    progress : callable, optional
        Called with the time point index after each solved time point.

    Returns
    -------
    RunResult
        ``steps[k]`` per time point: ``displacement_mm`` (3,) and ``rotation_rad`` (3,) of M,
        ``pressure_mpa`` (n_springs,), ``in_contact`` (n_springs,), ``contact_area_mm2``,
        ``peak_pressure_mpa``, residuals; ``warnings``; wall time; ``preflight``, what the springs
        saw before the first solve (:class:`edem.preflight.Preflight`).

    Raises
    ------
    InputError
        An unknown method.
    SolverError
        A time point without equilibrium (the message names it and says why), a scene the
        pre-flight refuses (springs out of reach, a load the constraints carry entirely), or a
        result whose springs are compressed past their length, the bones through each other
        (the time points and shares named; ``scene.allow_bone_overlap`` keeps it, warned).

    Warns
    -----
    EdemWarning
        Each of the scene's and the run's warnings (those ``summary.json`` lists).
    """
    result = run(scene, method, progress=progress)
    emit(list(scene.warnings) + result.warnings)
    return result

