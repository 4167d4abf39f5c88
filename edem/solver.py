"""DEM and EDEM over a load history (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs, docs/method.md#2-edem-the-time-dependent-incremental-method): the time loop around the static solve."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from edem.consistency import DEM_IMBALANCE_FRACTION, check_contact_kept, check_increment, remeasured_imbalance, remeasured_warning
from edem.errors import InputError, SolverError
from edem.joint_reaction import transfer_moment
from edem.laws import ElementLaw, stack_elements
from edem.mechanics import (
    DOF_NAMES,
    ShearTerms,
    UnilateralSolution,
    assemble_stiffness,
    generalised_directions,
    turn_rows,
    rotation_matrix,
    rotation_vector,
    solve_unilateral,
    unrestrained_dofs,
)
from edem.opensim_model import BodyPoses
from edem.preflight import Preflight, patch_resolution_warning, preflight
from edem.raycast import RayCaster
from edem.rowwise import row_dot
from edem.scene import Scene, Viscoelastic
from edem.springs import Cartilage, Placement, SpringGeometry, contact_law, ligament_elements, ligament_table, shear_terms, spring_geometry
from edem.thin_layer_contact import CoupledStep, coupled_layer_mesh
from edem.viscoelastic import check_rk2_stability, integrator_weights


#: the discrete methods: DEM (static, from M's initial pose at every time point) and EDEM (docs/method.md#2-edem-the-time-dependent-incremental-method)
METHODS = ("edem", "dem")


@dataclass
class StepResult:
    """One time point: the state every output file is written from (docs/result-format.md)."""

    step: int
    time_s: float
    force_n: np.ndarray  # applied load (3,)
    moment_nmm: np.ndarray
    displacement_mm: np.ndarray  # of G from its initial pose (EDEM: accumulated; DEM: this point)
    rotation_rad: np.ndarray  # rotation vector of M from its initial pose
    pressure_mpa: np.ndarray  # (n_springs,) normal contact pressure (elastic + viscous), 0 out of contact
    viscous_pressure_mpa: np.ndarray  # (n_springs,) the dashpots' share of it (0 without [viscoelastic])
    spring_length_mm: np.ndarray  # (n_springs,) at the start of the step, +inf where no hit
    in_contact: np.ndarray  # (n_springs,) bool
    ligament_force_n: np.ndarray  # (n_ligaments,) tension
    iterations: int
    force_residual_n: float
    moment_residual_nmm: float
    mobile_placement: Placement  # pose of M after the step (for the pressure maps)
    fixed_placement: Placement
    area_mm2: np.ndarray  # (n_springs,) spring areas
    # DEM: the load fraction the springs measured again at the solved pose leave unbalanced (None: EDEM)
    remeasured_imbalance: float | None = None
    # sum of p A n over the springs (N), its moment about G (N mm) and the centre of pressure (mm),
    # springs where the solve measured them (so they balance the load with ligaments and constraints)
    contact_force_n: np.ndarray = field(default_factory=lambda: np.zeros(3))
    contact_moment_nmm: np.ndarray = field(default_factory=lambda: np.zeros(3))
    centre_of_pressure_mm: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def contact_area_mm2(self) -> float:
        return float(self.area_mm2[self.in_contact].sum())

    @property
    def peak_pressure_mpa(self) -> float:
        return float(self.pressure_mpa.max(initial=0.0))

    @property
    def mean_pressure_mpa(self) -> float:
        """Total normal contact force over the contact area."""
        area = self.contact_area_mm2
        return float((self.pressure_mpa * self.area_mm2).sum() / area) if area > 0 else 0.0


@dataclass
class RunResult:
    scene: Scene
    method: str
    steps: list[StepResult]
    wall_time_s: float
    warnings: list[str]
    seconds: dict[str, float]  # wall time of the geometry stage (ray casting) and of the solves
    preflight: Preflight | None = None  # what the springs saw before the first solve (edem.preflight)

    @property
    def n_springs(self) -> int:
        return int(self.scene.spring_area_mm2.shape[0])


def fixed_placement(scene: Scene, step: int) -> Placement:
    """Pose of F at a time point: the joint angle about the scene's axis (docs/method.md#2-edem-the-time-dependent-incremental-method step 1), or the
    pose an OpenSim model gives it at the motion's coordinates."""
    kin = scene.kinematics
    if kin is None:
        return Placement.identity()
    if isinstance(kin, BodyPoses):  # F's full pose from an OpenSim model
        return Placement(kin.rotation[step], kin.translation_mm[step], np.zeros(3))
    rotation = rotation_matrix(kin.axis_direction * kin.angle_rad[step])
    return Placement(rotation, np.zeros(3), kin.axis_point_mm)


def weak_dofs_warning(
    directions: np.ndarray,
    law: ElementLaw,
    shear: ShearTerms | None,
    solution: UnilateralSolution,
    fixed_dofs: tuple[str, ...],
    length_scale_mm: float,
    ratio: float = 1e-4,
    coupled: bool = False,
) -> list[str]:
    """Warn about free DOFs that are restrained only by round-off-like stiffness (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs).

    A faceted cylinder's normals tilt slightly off radial, so sliding along its axis is not
    exactly singular but about 1e-5 as stiff as the rest: the solve succeeds and the body drifts.
    ``coupled``: the active rows are weighed by their columns' small-strain stiffness. A coupled
    layer's surface moves by C f, not by g . u, so its columns' law at g . u means nothing (and
    is not finite past a log column's range); the layer restrains the same DOFs as its rows.
    """
    approach = np.zeros(directions.shape[0]) if coupled else directions @ solution.displacement
    _, stiffness = law.force_and_stiffness(approach)
    k = assemble_stiffness(directions, stiffness, solution.active, shear)
    free = np.array([d not in fixed_dofs for d in DOF_NAMES])
    weak = unrestrained_dofs(k, free, length_scale_mm, rtol=ratio)
    if not weak:
        return []
    return [
        f"the contact barely resists motion along {', '.join(weak)} (stiffness below {ratio:g} of the largest, "
        "e.g. sliding along a faceted cylinder's axis): consider fixing these DOFs in [constraints] fixed_dofs"
    ]


def precompression_warning(geometry: SpringGeometry, cartilage: Cartilage) -> list[str]:
    """Say so when a gap-law bed starts compressed (t larger than the gap h): it pushes the
    bodies apart before any load, so the first time point's result includes that preload."""
    if cartilage.thickness_mm is None:
        return []
    t = float(cartilage.thickness_mm)
    h = geometry.candidate_length_mm
    compressed = h < t * (1.0 - 1e-9)
    if not np.any(compressed):
        return []
    return [
        f"the {cartilage.law} bed starts pre-compressed: {int(compressed.sum())} springs are shorter than the "
        f"thickness t = {t:g} mm, by up to {float((t - h).max()):.3g} mm (the gap between the surfaces is less "
        "than t): the bodies push apart before any load; check thickness_mm against the gap"
    ]


def compression_ratio(geometry: SpringGeometry, cartilage: Cartilage, approach_mm: np.ndarray) -> np.ndarray:
    """Compression over undeformed length of the candidate springs after an approach (strain)."""
    return cartilage.spring_law.strain(geometry.candidate_length_mm, approach_mm, cartilage.thickness_mm)


def applied_loads(scene: Scene) -> np.ndarray:
    """(n, 6) force and moment about G per time point in global axes (turned with F for frame = "fixed").

    A moment given about another point (``load.point_mm``, e.g. a JointReaction's joint centre,
    placed with F for frame = "fixed") is moved to G: M_G = M_P + (P - G) x F.
    """
    load = scene.load
    force, moment, point = load.force_n, load.moment_nmm, load.point_mm
    if load.frame == "fixed" and scene.kinematics is not None:
        placements = [fixed_placement(scene, k) for k in range(len(load.time_s))]
        rotations = [p.rotation for p in placements]
        force = np.einsum("kij,kj->ki", rotations, force)
        moment = np.einsum("kij,kj->ki", rotations, moment)
        if point is not None:
            point = np.array([p.points(x[None])[0] for p, x in zip(placements, point)])
    if point is not None:
        moment = transfer_moment(moment, force, point, scene.reference_point_mm)
    return np.hstack([force, moment])


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
    With ``cartilage.coupling = "thin-layer"`` each solve is the coupled layer's
    (:mod:`edem.thin_layer_contact`) and the committed forces are its coupled pressure field.
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
    arm_squared = ((spring_centroid - g0) ** 2).sum(axis=1)
    length_scale = float(np.sqrt(arm_squared.mean()))
    # Distance of the furthest spring from G: no rigid motion of M changes it (check_increment's bound).
    arm_bound = float(np.sqrt(arm_squared.max(initial=0.0)))
    load = scene.load
    loads = applied_loads(scene)
    warnings: list[str] = constrained_moment_warning(loads, scene.fixed_dofs)
    viscous = scene.viscoelastic if method == "edem" else None
    if scene.viscoelastic is not None and viscous is None:
        warnings.append("[viscoelastic] is ignored by DEM, a static method: use --method edem")
    if viscous is not None and viscous.integrator == "rk2":
        warnings += check_rk2_stability(load.time_s, viscous.relaxation_time_s, viscous.allow_unstable, scene.source)
    # Committed (elastic) spring forces, the EDEM push-back, one row per axis (3, n): gathers and
    # scatters of the candidates' columns run along contiguous rows (several times cheaper than
    # over (n, 3) rows).
    stored = np.zeros((3, n_springs))
    pose = Placement.identity(g0)
    layer_mesh = coupled_layer_mesh(scene) if cartilage.coupling == "thin-layer" else None
    released = None
    steps: list[StepResult] = []
    unbalanced: list[tuple[int, float]] = []  # DEM time points whose re-measured springs miss the load
    free = np.array([d not in scene.fixed_dofs for d in DOF_NAMES])
    ligaments = ligament_table(scene.ligaments)
    reference_rows = generalised_directions(spring_centroid, spring_normal, g0)
    rays = caster.prepare(spring_centroid, spring_normal)  # checked once, cast at every time point
    report = preflight(scene, loads, lambda k: fixed_placement(scene, k), caster, rays)
    seconds = {"geometry": 0.0, "solve": 0.0}
    for k, t in enumerate(load.time_s):
        clock = time.perf_counter()
        if method == "dem":
            pose, stored = Placement.identity(g0), np.zeros((3, n_springs))
        f_pose = fixed_placement(scene, k)
        geometry = spring_geometry(spring_centroid, spring_normal, spring_area, pose, caster, f_pose, cartilage, rays)
        seconds["geometry"] += time.perf_counter() - clock
        clock = time.perf_counter()
        n_c = int(geometry.candidate_index.size)
        if cartilage.spring_law.needs_positive_length and np.any(geometry.candidate_length_mm <= 0.0):
            # k = E'/h (threshold) and p = -E' ln(h/t) (gap-log) have no meaning once h <= 0.
            bad = int((geometry.candidate_length_mm <= 0.0).sum())
            raise SolverError(
                f"time point {k} (t = {t:g} s): {bad} springs are compressed past their length "
                f"(h <= 0, the bodies interpenetrate); the {cartilage.law} law needs h > 0: "
                + ("use more time points so each increment is small, or the linear gap law" if k else "separate the bodies or use the linear gap law")
            )
        if n_c == 0 and not scene.ligaments and np.any(loads[k]):
            raise SolverError(
                f"time point {k} (t = {t:g} s): no spring is a candidate: no part of the fixed body lies "
                f"within h_max = {cartilage.max_spring_length_mm:g} mm of the mobile body along its normals"
            )
        g_current = pose.points(g0[None])[0]
        # Gather the candidates once by index (cheaper than repeated boolean masks over all springs).
        cand_idx = geometry.candidate_index
        lig_rows, lig_law, _ = ligament_elements(ligaments, pose, f_pose, g_current)
        # Rows g = (n, (c - G) x n) of the candidates: both parts turn with M, so they are the
        # reference rows (built once) turned by M's rotation; one gather and one product.
        directions = turn_rows(np.take(reference_rows, cand_idx, axis=0), pose.rotation, len(lig_rows))
        directions[n_c:] = lig_rows
        normals = directions[:n_c, :3]
        area_c = spring_area[cand_idx]
        stored_c = np.take(stored, cand_idx, axis=1).T
        stored_normal = row_dot(stored_c, normals)
        # (the tangential part of the stored forces only matters, and is only formed, with shear)
        shear = shear_terms(geometry, cartilage, g_current, stored_c - stored_normal[:, None] * normals) if cartilage.shear_modulus_mpa else None
        law = stack_elements(contact_law(geometry, cartilage, stored_normal), lig_law)
        try:
            if layer_mesh is None:
                solution = solve_unilateral(
                    directions, law, loads[k], fixed_dofs=scene.fixed_dofs, shear=shear, length_scale_mm=length_scale
                )
            else:
                coupled = CoupledStep.build(layer_mesh, geometry, cartilage, stored_normal, directions[:n_c], lig_rows, lig_law)
                solution = coupled.solve(loads[k], scene.fixed_dofs, shear, length_scale, released)
                released = np.zeros(n_springs, bool)  # the candidates out of contact: the next solve's first guess
                released[cand_idx] = ~solution.active[:n_c]
        except SolverError as exc:
            cause = (
                f" (no spring is a candidate here: no part of the fixed body lies within h_max = "
                f"{cartilage.max_spring_length_mm:g} mm of the mobile body along its normals, so only the ligaments resist)"
                if n_c == 0 else ""
            )
            raise SolverError(f"time point {k} (t = {t:g} s, {n_c} candidate springs): {exc}{cause}") from None
        total_force = np.where(solution.active, solution.element_force_n, 0.0)
        if layer_mesh is not None and solution.max_penetration_mm > 1e-9 * cartilage.max_spring_length_mm:
            warnings.append(f"time point {k} (t = {t:g} s): the layer's surface penetrates the fixed body by {solution.max_penetration_mm:.3g} mm out of contact")
        if k == 0:
            warnings += precompression_warning(geometry, cartilage)
            if layer_mesh is not None:
                warnings += coupled.resolution_warning(layer_mesh)
            warnings += weak_dofs_warning(directions, law, shear, solution, scene.fixed_dofs, length_scale, coupled=layer_mesh is not None)
        overstrained = int((solution.active[:n_c] & (compression_ratio(geometry, cartilage, directions[:n_c] @ solution.displacement) >= 1.0)).sum())
        if overstrained:
            warnings.append(
                f"time point {k} (t = {t:g} s): {overstrained} springs compressed past their length "
                "(strain >= 100 %): the spring bed is outside its range" + (", use more time points" if method == "edem" else "")
            )
        if viscous is None:
            u, elastic_force = solution.displacement, total_force
        else:
            dt = float(t - load.time_s[k - 1]) if k else 0.0
            previous = loads[k - 1] if k else np.zeros(6)
            if layer_mesh is None:
                u, elastic_force = viscoelastic_increment(
                    directions, law, shear, solution, previous, loads[k], dt, viscous, scene.fixed_dofs
                )
            else:
                weights = integrator_weights(dt, viscous.relaxation_time_s, viscous.integrator)
                u, elastic_force = coupled.viscoelastic_increment(solution, stored_normal, previous, loads[k], weights, shear, scene.fixed_dofs)
            if not np.all(np.isfinite(u)):
                raise SolverError(f"time point {k} (t = {t:g} s): the viscoelastic integration diverged (non-finite displacement)")
        # Overflowed numbers pass every comparison below (NaN > limit is False): refuse them here.
        if not (np.all(np.isfinite(u)) and np.all(np.isfinite(elastic_force))):
            raise SolverError(
                f"time point {k} (t = {t:g} s): the solution diverged (non-finite displacement or spring forces; "
                f"load {np.abs(loads[k]).max():.3g} against {n_c} springs of modulus {cartilage.youngs_modulus_mpa:g} MPa): "
                "check the load's units and scale and the cartilage modulus"
            )
        contact = directions[:n_c].T @ total_force[:n_c]
        if shear is not None:
            contact = contact + shear.generalised_force(solution.displacement, solution.active[:n_c])
        spring_force = total_force[:n_c]
        # sum f (R X + b) / sum f = R (sum f X / sum f) + b: the candidates' centroids are only
        # placed at the pose if check_increment needs them.
        force_sum = spring_force.sum()
        centre = pose.points((spring_force @ np.take(spring_centroid, cand_idx, axis=0))[None] / force_sum)[0] if force_sum > 0 else g_current
        where = f"time point {k} (t = {t:g} s)"
        n_contact = int(solution.active[:n_c].sum())
        if not n_contact:  # (M's normals at the pose are only formed for this check)
            check_contact_kept(loads[k, :3], geometry.normal, spring_area, n_contact, free, u, where)
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
        pose = Placement(rotation_matrix(u[3:]) @ pose.rotation, pose.translation_mm + u[:3], g0)
        # The re-measure evaluates the independent springs' law at the solved pose: it says
        # nothing about the coupled layer, whose forces are not a function of each spring's length.
        if method == "dem" and layer_mesh is None:
            clock_remeasure = time.perf_counter()
            imbalance, scale = remeasured_imbalance(
                pose=pose, fixed_pose=f_pose, initial=geometry, spring_centroid_mm=spring_centroid, spring_normal=spring_normal,
                spring_area_mm2=spring_area, caster=caster, cartilage=cartilage, ligaments=scene.ligaments, reference_point_mm=g0,
                shear=shear, u=u, active=solution.active, model_force_n=total_force, load=loads[k], free=free, length_scale_mm=length_scale,
            )
            seconds["geometry"] += time.perf_counter() - clock_remeasure
            clock += time.perf_counter() - clock_remeasure  # counted as geometry, not as solve
            remeasured = imbalance / scale if scale > 0 else 0.0
            if remeasured > DEM_IMBALANCE_FRACTION:
                unbalanced.append((k, remeasured))
        pressure = np.zeros(n_springs)
        pressure[cand_idx] = total_force[:n_c] / area_c
        viscous_pressure = np.zeros(n_springs)
        if viscous is not None:
            viscous_pressure[cand_idx] = (total_force[:n_c] - elastic_force[:n_c]) / area_c
        in_contact = np.zeros(n_springs, bool)
        in_contact[cand_idx] = solution.active[:n_c]
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
                remeasured_imbalance=remeasured if method == "dem" and layer_mesh is None else None,
                contact_force_n=contact[:3],
                contact_moment_nmm=contact[3:],
                centre_of_pressure_mm=centre,
            )
        )
        if progress is not None:
            progress(k)
    if unbalanced:
        worst = max(unbalanced, key=lambda item: item[1])
        warnings.append(remeasured_warning(len(unbalanced), worst[0], worst[1]))
    warnings += patch_resolution_warning(steps)
    return RunResult(scene, method, steps, time.perf_counter() - started, warnings, seconds, report)


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
        A time point without equilibrium (the message names it and says why), or a scene the
        pre-flight refuses (springs out of reach, a load the constraints carry entirely).
    """
    return run(scene, method, progress=progress)


def viscoelastic_increment(
    directions: np.ndarray,
    law: ElementLaw,
    shear: ShearTerms | None,
    elastic: UnilateralSolution,
    previous_load: np.ndarray,
    load: np.ndarray,
    dt_s: float,
    viscous: Viscoelastic,
    fixed_dofs: tuple[str, ...],
) -> tuple[np.ndarray, np.ndarray]:
    """Kelvin-Voigt increment u = K^-1 [phi (T_{k-1} - p) + psi (T_k - T_{k-1})] (docs/method.md#4-viscoelastic-edem-thesis-chapter-6, eq. 6.18).

    ``elastic`` is the quasi-static solve under T_k: its forces are the total (elastic + viscous)
    spring forces at the end of the step and its active set is the contact set. Springs that still
    hold an elastic force while the total force has vanished (the load went to zero) stay in the set
    so they can creep back. Returns the increment and the elastic element forces to commit.
    """
    phi, psi = integrator_weights(dt_s, viscous.relaxation_time_s, viscous.integrator)
    force0, stiffness0 = law.force_and_stiffness(np.zeros(directions.shape[0]))
    scale = 1e-9 * max(float(np.abs(force0).max(initial=0.0)), float(np.abs(load).max()), 1e-300)
    active = elastic.active | ((force0 > 0) & (elastic.element_force_n >= -scale))
    free = np.array([d not in fixed_dofs for d in DOF_NAMES])
    u = np.zeros(6)
    if np.any(active) and (phi or psi):
        n_shear = 0 if shear is None else shear.normals.shape[0]
        pushback = directions.T @ np.where(active, force0, 0.0)
        if shear is not None:
            pushback = pushback + shear.generalised_force(np.zeros(6), active[:n_shear])
        k = assemble_stiffness(directions, stiffness0, active, shear)
        rhs = phi * (previous_load - pushback) + psi * (load - previous_load)
        u[free] = np.linalg.lstsq(k[np.ix_(free, free)], rhs[free], rcond=None)[0]
    force, _ = law.force_and_stiffness(directions @ u)
    return u, np.where(active, np.maximum(force, 0.0), 0.0)
