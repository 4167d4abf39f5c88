"""DEM and EDEM over a load history (SPEC 2-3): the time loop around the static solve."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from edem.errors import SolverError
from edem.mechanics import NormalLaw, rotation_matrix, rotation_vector, solve_unilateral
from edem.raycast import RayCaster
from edem.scene import Scene
from edem.springs import Placement, contact_law, ligament_elements, shear_terms, spring_geometry


@dataclass
class StepResult:
    """One time point: the state every output file is written from (SPEC 9)."""

    step: int
    time_s: float
    force_n: np.ndarray  # applied load (3,)
    moment_nmm: np.ndarray
    displacement_mm: np.ndarray  # of G from its initial pose (EDEM: accumulated; DEM: this point)
    rotation_rad: np.ndarray  # rotation vector of M from its initial pose
    pressure_mpa: np.ndarray  # (n_springs,) normal contact pressure, 0 out of contact
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

    @property
    def n_springs(self) -> int:
        return int(self.scene.spring_area_mm2.shape[0])


def fixed_placement(scene: Scene, step: int) -> Placement:
    """Pose of F at a time point: the joint angle about the scene's axis (SPEC 3 step 1)."""
    kin = scene.kinematics
    if kin is None:
        return Placement.identity()
    rotation = rotation_matrix(kin.axis_direction * kin.angle_rad[step])
    return Placement(rotation, np.zeros(3), kin.axis_point_mm)


def run(
    scene: Scene,
    method: str | None = None,
    *,
    caster: RayCaster | None = None,
    progress: Callable[[int], None] | None = None,
) -> RunResult:
    """Solve every time point of the scene with DEM (static, from M's initial pose) or EDEM.

    EDEM (SPEC 3): at each step the geometry is redone at M's accumulated pose and F's pose for
    that time, the stored spring forces of the springs still in contact push back (eq. 3.17),
    the increment solves K u = T_k - p with the active set handled as in DEM (eq. 3.18-3.19),
    then the forces are committed and M is moved by u. Springs that left contact keep no force.
    """
    method = method or scene.method
    if method not in ("dem", "edem"):
        raise ValueError(f"unknown method {method!r}")
    started = time.perf_counter()
    caster = caster or RayCaster(scene.fixed.vertices_mm, scene.fixed.triangles)
    cartilage = scene.cartilage
    g0 = scene.reference_point_mm
    n_springs = scene.spring_area_mm2.shape[0]
    length_scale = float(np.sqrt(((scene.spring_centroid_mm - g0) ** 2).sum(axis=1).mean()))
    stored = np.zeros((n_springs, 3))
    pose = Placement.identity(g0)
    steps: list[StepResult] = []
    warnings: list[str] = []
    load = scene.load
    for k, t in enumerate(load.time_s):
        if method == "dem":
            pose, stored = Placement.identity(g0), np.zeros((n_springs, 3))
        f_pose = fixed_placement(scene, k)
        geometry = spring_geometry(
            scene.spring_centroid_mm, scene.spring_normal, scene.spring_area_mm2, pose, caster, f_pose, cartilage
        )
        cand = geometry.candidate
        if cartilage.law == "threshold" and np.any(geometry.spring_length_mm[cand] <= 0.0):
            bad = int((geometry.spring_length_mm[cand] <= 0.0).sum())
            raise SolverError(
                f"time point {k} (t = {t:g} s): {bad} springs are compressed past their length "
                "(h <= 0, the bodies interpenetrate); the threshold law needs h > 0: "
                + ("use more time points so each increment is small, or the gap-log law" if k else "separate the bodies or use the gap-log law")
            )
        g_current = pose.points(g0[None])[0]
        normals = geometry.normal[cand]
        stored_c = stored[cand]
        stored_normal = np.einsum("ij,ij->i", stored_c, normals)
        law = contact_law(geometry, cartilage, stored_normal)
        shear = shear_terms(geometry, cartilage, g_current, stored_c - stored_normal[:, None] * normals)
        lig_rows, lig_law, _ = ligament_elements(scene.ligaments, pose, f_pose, g_current)
        directions = np.vstack([geometry.directions(g_current)[cand], lig_rows])
        try:
            solution = solve_unilateral(
                directions,
                NormalLaw.concatenate(law, lig_law),
                np.concatenate([load.force_n[k], load.moment_nmm[k]]),
                fixed_dofs=scene.fixed_dofs,
                shear=shear,
                length_scale_mm=length_scale,
            )
        except SolverError as exc:
            raise SolverError(f"time point {k} (t = {t:g} s, {int(cand.sum())} candidate springs): {exc}") from None
        n_c = int(cand.sum())
        s = solution.element_force_n
        active = solution.active
        spring_force = np.where(active[:n_c], s[:n_c], 0.0)
        committed = spring_force[:, None] * normals
        if shear is not None:
            committed = committed + shear.force(solution.displacement, active[:n_c])
        stored = np.zeros((n_springs, 3))
        stored[cand] = committed
        u = solution.displacement
        pose = Placement(rotation_matrix(u[3:]) @ pose.rotation, pose.translation_mm + u[:3], g0)
        pressure = np.zeros(n_springs)
        pressure[cand] = spring_force / geometry.area_mm2[cand]
        in_contact = np.zeros(n_springs, bool)
        in_contact[cand] = active[:n_c]
        steps.append(
            StepResult(
                step=k,
                time_s=float(t),
                force_n=load.force_n[k].copy(),
                moment_nmm=load.moment_nmm[k].copy(),
                displacement_mm=pose.translation_mm.copy(),
                rotation_rad=rotation_vector(pose.rotation),
                pressure_mpa=pressure,
                spring_length_mm=geometry.spring_length_mm,
                in_contact=in_contact,
                ligament_force_n=np.where(active[n_c:], s[n_c:], 0.0),
                iterations=solution.iterations,
                force_residual_n=solution.force_residual_n,
                moment_residual_nmm=solution.moment_residual_nmm,
                mobile_placement=pose,
                fixed_placement=f_pose,
                area_mm2=scene.spring_area_mm2,
            )
        )
        if progress is not None:
            progress(k)
    return RunResult(scene, method, steps, time.perf_counter() - started, warnings)
