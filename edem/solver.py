"""DEM and EDEM over a load history (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs, docs/method.md#2-edem-the-time-dependent-incremental-method): the time loop around the static solve."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from edem.errors import InputError, SolverError
from edem.laws import ElementLaw, stack_elements
from edem.mechanics import (
    DOF_NAMES,
    ShearTerms,
    UnilateralSolution,
    assemble_stiffness,
    generalised_directions,
    rotation_matrix,
    rotation_vector,
    solve_unilateral,
    unrestrained_dofs,
)
from edem.raycast import RayCaster
from edem.scene import Scene, Viscoelastic
from edem.springs import Cartilage, Placement, SpringGeometry, contact_law, ligament_elements, shear_terms, spring_geometry
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

    @property
    def n_springs(self) -> int:
        return int(self.scene.spring_area_mm2.shape[0])


def fixed_placement(scene: Scene, step: int) -> Placement:
    """Pose of F at a time point: the joint angle about the scene's axis (docs/method.md#2-edem-the-time-dependent-incremental-method step 1)."""
    kin = scene.kinematics
    if kin is None:
        return Placement.identity()
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
) -> list[str]:
    """Warn about free DOFs that are restrained only by round-off-like stiffness (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs).

    A faceted cylinder's normals tilt slightly off radial, so sliding along its axis is not
    exactly singular but about 1e-5 as stiff as the rest: the solve succeeds and the body drifts.
    """
    _, stiffness = law.force_and_stiffness(directions @ solution.displacement)
    k = assemble_stiffness(directions, stiffness, solution.active, shear)
    free = np.array([d not in fixed_dofs for d in DOF_NAMES])
    weak = unrestrained_dofs(k, free, length_scale_mm, rtol=ratio)
    if not weak:
        return []
    return [
        f"the contact barely resists motion along {', '.join(weak)} (stiffness below {ratio:g} of the largest, "
        "e.g. sliding along a faceted cylinder's axis): consider fixing these DOFs in [constraints] fixed_dofs"
    ]


def compression_ratio(geometry: SpringGeometry, cartilage: Cartilage, approach_mm: np.ndarray) -> np.ndarray:
    """Compression over undeformed length of the candidate springs after an approach (strain)."""
    return cartilage.spring_law.strain(geometry.spring_length_mm[geometry.candidate], approach_mm, cartilage.thickness_mm)


def applied_loads(scene: Scene) -> np.ndarray:
    """(n, 6) force and moment per time point in global axes (turned with F for frame = "fixed")."""
    load = scene.load
    force, moment = load.force_n, load.moment_nmm
    if load.frame == "fixed" and scene.kinematics is not None:
        rotations = [fixed_placement(scene, k).rotation for k in range(len(load.time_s))]
        force = np.einsum("kij,kj->ki", rotations, force)
        moment = np.einsum("kij,kj->ki", rotations, moment)
    return np.hstack([force, moment])


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
    length_scale = float(np.sqrt(((spring_centroid - g0) ** 2).sum(axis=1).mean()))
    load = scene.load
    loads = applied_loads(scene)
    warnings: list[str] = []
    viscous = scene.viscoelastic if method == "edem" else None
    if scene.viscoelastic is not None and viscous is None:
        warnings.append("[viscoelastic] is ignored by DEM, a static method: use --method edem")
    if viscous is not None and viscous.integrator == "rk2":
        warnings += check_rk2_stability(load.time_s, viscous.relaxation_time_s, viscous.allow_unstable, scene.source)
    stored = np.zeros((n_springs, 3))  # committed (elastic) spring forces: the EDEM push-back
    pose = Placement.identity(g0)
    steps: list[StepResult] = []
    seconds = {"geometry": 0.0, "solve": 0.0}
    for k, t in enumerate(load.time_s):
        clock = time.perf_counter()
        if method == "dem":
            pose, stored = Placement.identity(g0), np.zeros((n_springs, 3))
        f_pose = fixed_placement(scene, k)
        geometry = spring_geometry(spring_centroid, spring_normal, spring_area, pose, caster, f_pose, cartilage)
        seconds["geometry"] += time.perf_counter() - clock
        clock = time.perf_counter()
        cand = geometry.candidate
        n_c = int(cand.sum())
        if cartilage.spring_law.needs_positive_length and np.any(geometry.spring_length_mm[cand] <= 0.0):
            # k = E'/h (threshold) and p = -E' ln(h/t) (gap-log) have no meaning once h <= 0.
            bad = int((geometry.spring_length_mm[cand] <= 0.0).sum())
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
        normals = geometry.normal[cand]
        stored_c = stored[cand]
        stored_normal = np.einsum("ij,ij->i", stored_c, normals)
        shear = shear_terms(geometry, cartilage, g_current, stored_c - stored_normal[:, None] * normals)
        lig_rows, lig_law, _ = ligament_elements(scene.ligaments, pose, f_pose, g_current)
        law = stack_elements(contact_law(geometry, cartilage, stored_normal), lig_law)
        directions = generalised_directions(geometry.centroid_mm[cand], normals, g_current)
        if len(lig_rows):
            directions = np.vstack([directions, lig_rows])
        try:
            solution = solve_unilateral(
                directions, law, loads[k], fixed_dofs=scene.fixed_dofs, shear=shear, length_scale_mm=length_scale
            )
        except SolverError as exc:
            raise SolverError(f"time point {k} (t = {t:g} s, {n_c} candidate springs): {exc}") from None
        total_force = np.where(solution.active, solution.element_force_n, 0.0)
        if k == 0:
            warnings += weak_dofs_warning(directions, law, shear, solution, scene.fixed_dofs, length_scale)
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
            u, elastic_force = viscoelastic_increment(
                directions, law, shear, solution, previous, loads[k], dt, viscous, scene.fixed_dofs
            )
            if not np.all(np.isfinite(u)):
                raise SolverError(f"time point {k} (t = {t:g} s): the viscoelastic integration diverged (non-finite displacement)")
        committed = elastic_force[:n_c, None] * normals
        if shear is not None:
            committed = committed + shear.force(u, solution.active[:n_c])
        stored = np.zeros((n_springs, 3))
        stored[cand] = committed
        pose = Placement(rotation_matrix(u[3:]) @ pose.rotation, pose.translation_mm + u[:3], g0)
        pressure = np.zeros(n_springs)
        pressure[cand] = total_force[:n_c] / spring_area[cand]
        viscous_pressure = np.zeros(n_springs)
        viscous_pressure[cand] = (total_force[:n_c] - elastic_force[:n_c]) / spring_area[cand]
        in_contact = np.zeros(n_springs, bool)
        in_contact[cand] = solution.active[:n_c]
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
            )
        )
        if progress is not None:
            progress(k)
    return RunResult(scene, method, steps, time.perf_counter() - started, warnings, seconds)


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
        ``peak_pressure_mpa``, residuals; ``warnings``; wall time.

    Raises
    ------
    InputError
        An unknown method.
    SolverError
        A time point without equilibrium (the message names it and says why).
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
