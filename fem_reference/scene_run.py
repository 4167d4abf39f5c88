"""The FE reference of a whole scene (docs/method.md#6-the-fe-reference-and-its-discrete-twins, docs/result-format.md): ``edem fe SCENE``.

:func:`run_scene` solves, for each selected time point of a scene, one force-controlled
frictionless FE contact problem (:func:`fem_reference.contact.solve_contact`) and writes the same
result directory as ``edem run``. How the time points relate is the scene's time stepping
(:mod:`fem_reference.time_stepping`).

Models (docs/method.md#6-the-fe-reference-and-its-discrete-twins): :data:`fem_reference.models.FE_MODELS` (``slab``, the twin of the ``threshold``
law, and ``layer``, the twin of the ``gap`` laws), built with :mod:`geometries.fe_solids`.

The obstacle is F's triangulation at the time point's pose (:class:`RigidSurface`); the load is
:meth:`edem.scene.Scene.applied_loads` of that time point; the free rigid motions of the bone are the
scene's free DOFs (``[constraints] fixed_dofs``), rotations about G = ``reference_point_mm``
(small rotations: ``q x (x - G)``). Frictionless contact cannot resist a free motion along which
every contact normal is perpendicular (a bone sliding along a flat tibia): such a motion is fixed
in the FE with a warning when the load has no component along it, and the time point is refused
otherwise. Ligaments are not modelled (warning when the scene has some).

Each time point is independent (the DEM convention: displacement of G from the initial pose of
that time point; :class:`fem_reference.time_stepping.ElasticStepping`), except with
``[viscoelastic]``: the Kelvin-Voigt continuum (:class:`fem_reference.time_stepping.KelvinVoigtStepping`,
:mod:`fem_reference.viscoelastic`) solves every time point up to the last selected one, in
order, on one mesh, and reports the creeping displacement; and likewise with ``[fe] material =
"biphasic"`` the biphasic layer (:class:`fem_reference.time_stepping.BiphasicStepping`,
:mod:`fem_reference.biphasic_contact`), which creeps by its fluid flow. Consecutive time points with the same
geometry (no kinematics, or the layer at the same joint angle) reuse the mesh; the elastic ones
start Newton from the previous solution scaled to the new load (exact for a slab whose contact
set does not change: 0 Newton iterations).

Defaults (arguments > the scene's ``[fe]`` table > these, :mod:`fem_reference.settings`): model = the twin of the scene's law;
degree 2 (P2; Taylor-Hood P2-P1 from nu = 0.49) at ``mesh_size_mm`` = 1.0, or P1 at 0.5 with
degree 1. The size is the target in-plane edge (M's triangles are midpoint-subdivided until
their mean edge is at most the size, so it acts in factors of 2) and sets the layers through the
thickness, ceil(thickness / size). Measured on the ideal ankle standing (slab, 333 N, nu = 0.42,
2 shared cores): P2 at 1.0 mm 71 k DOFs, about 20 s and 1 GB, within 0.7 % (peak pressure,
displacement, contact area) of P2 at 0.7 mm (402 k DOFs, 8 min, 8 GB); P1 at 0.5 mm 71 k DOFs,
about 23 s, within 2 %; P1 at 1.0 mm 10 k DOFs, 2-4 s, within 2.5 % (a quick look).

Result directory (docs/result-format.md, the layout of ``edem run``, written by :mod:`edem.resultdir`): summary.json (``n_dofs`` for
``n_springs``, plus element, mesh size, Newton iterations, strains, the contact-area
definitions), timeseries.csv with exactly ``edem.resultdir.TIMESERIES_COLUMNS`` (``iterations`` =
Newton iterations), pressure.pvd + pressure_NNNN.vtp per solved time point: the FE contact
surface in the reference configuration of that time point (point data: nodal pressure_mpa,
spring_length_mm = local slab thickness or layer thickness + initial gap, in_contact, gap_mm;
cell data: the facet averages and in_contact of the average) and fixed.vtp (F as in the scene).
For comparisons with the springs, which live on M: point data ``mobile_point_mm`` (the point of
M under each contact-surface point, along its column) and ``pressure_on_mobile_mpa`` (point and
cell data: the pressure times the columns' area ratio contact face / M, i.e. the force per area
of M) and the summary's ``max_contact_area_on_mobile_mm2``. On a curved M the columns fan out:
on the ideal ankle the slab's contact face has 525 mm^2 over 463 mm^2 of M.

Only rank 0 writes files; the sums and gathers are collective, so ``mpirun -n N`` works.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from scipy.spatial import cKDTree

from edem.mechanics import DOF_NAMES
from edem.raycast import RayCaster
from edem.resultdir import Frame, Provenance, SurfaceFrame, timeseries_row, write_run
from fem_reference.fe_stack import fe_modules
from fem_reference.models import FE_MODELS, FEGeometry, contact_refinement, contact_surface
from fem_reference.problem import (
    AREA_DEFINITION_NITSCHE,
    FEContactProblem,
    FEMesh,
    RigidSurface,
    SolverOptions,
)
from fem_reference.progress import SolveProgress
from fem_reference.settings import FESettings, resolve_settings
from fem_reference.time_stepping import TimePoint, time_stepping
from geometries.errors import InputError, SolverError
from geometries.triangle_kernels import triangle_areas

#: Free rigid motions whose contact stiffness is below this fraction of the largest are fixed.
WEAK_MODE_RATIO = 1e-8

STRAIN_WARNING = 0.10
AREA_ON_MOBILE_DEFINITION = (
    "the contact indicator of contact_area_definition weighted, facet by facet, by the area of "
    "the triangle where the facet's columns cross M's scene surface (the bonded face, or with a "
    "bone mesh under M its articular surface) over the facet's own area: the contact area "
    "measured on M, as the springs measure it (the slab's columns fan out along M's normals, so "
    "its contact face is larger than the candidate surface)")
NOMINAL_STRAIN_DEFINITION = (
    "max over the contact-surface nodes in contact of the compression over the undeformed "
    "thickness: (approach of the rigid bone motion along the obstacle normal - initial gap) / "
    "(local slab thickness, or the layer thickness); max_principal_strain is the FE's largest "
    "|principal strain| at cell midpoints, which grows under refinement at the bonded edges")


@dataclass
class FEStepResult:
    """One solved time point (the state timeseries.csv and pressure_NNNN.vtp are written from)."""

    step: int
    time_s: float
    force_n: np.ndarray
    moment_nmm: np.ndarray
    displacement_mm: np.ndarray  # of G (the bone translation)
    rotation_rad: np.ndarray  # small rotation vector of the bone about G (0 when fixed)
    peak_pressure_mpa: float
    mean_pressure_mpa: float
    contact_area_mm2: float  # on the FE contact surface (see AREA_DEFINITION_NITSCHE)
    contact_area_on_mobile_mm2: float  # the same indicator mapped onto M (see summary)
    iterations: int  # Newton iterations
    force_residual_n: float
    moment_residual_nmm: float
    n_dofs: int
    wall_time_s: float
    max_nominal_strain: float  # max over contact nodes of (rigid approach - gap) / thickness
    max_principal_strain: float  # FE, max |principal strain| at cell midpoints
    contact_force_n: np.ndarray
    constraint_force_n: np.ndarray
    # the FE contact surface (reference configuration of this time point) and its data
    points_mm: np.ndarray
    triangles: np.ndarray
    point_data: dict[str, np.ndarray]
    cell_data: dict[str, np.ndarray]
    mean_edge_mm: float = 0.0
    layers: int = 0
    warnings: list[str] = field(default_factory=list)
    linear_solver: str = ""  # the inner solve used: "direct" or "iterative"; "" when nothing was solved
    krylov_iterations: int = 0  # iterative path: inner Krylov iterations over the time point's solves
    krylov_iterations_per_step: list[int] = field(default_factory=list)  # iterative path: per Newton step


@dataclass
class FERunResult:
    """All solved time points of one scene, and its result directory's content (the contract of
    :class:`edem.resultdir.RunOutput`; the FE writes no fixed.pvd and no timeseries.sto)."""

    opensim_sto: ClassVar[bool] = False

    scene: Any
    settings: FESettings
    steps: list[FEStepResult]
    wall_time_s: float
    warnings: list[str]
    n_time_points: int
    out_dir: Path | None = None
    rank: int = 0
    peak_memory_bytes: float | None = None  # this rank's peak resident set during the run
    time_stepping_summary: dict[str, Any] = field(default_factory=dict)  # its keys in summary.json

    @property
    def method(self) -> str:
        return self.settings.method

    @property
    def n_dofs(self) -> int:
        return max((s.n_dofs for s in self.steps), default=0)

    def summary(self) -> dict[str, Any]:
        """summary.json (docs/result-format.md keys, ``n_dofs`` for ``n_springs``, plus the FE details)."""
        steps = self.steps
        last = steps[-1]
        s = self.settings
        return {
            "scene": self.scene.name,
            "method": self.method,
            "steps": len(steps),
            "n_dofs": self.n_dofs,
            "wall_time_s": float(self.wall_time_s),
            "peak_memory_mb": None if self.peak_memory_bytes is None else self.peak_memory_bytes / 1e6,
            # the raw nodal peak on the contact face (reported only); peak_pressure_on_mobile_mpa is the
            # same field as force per area of M, as the campaigns compare it (x the columns' area
            # ratio: larger where the columns fan out); both are mesh-dependent at a sharp contact
            # edge, regularised_peak_pressure_mpa (edem.resultdir) is the judged one
            "peak_pressure_mpa": max(float(x.peak_pressure_mpa) for x in steps),
            "peak_pressure_on_mobile_mpa": max(float(np.max(x.point_data["pressure_on_mobile_mpa"], initial=0.0)) for x in steps),
            "max_contact_area_mm2": max(float(x.contact_area_mm2) for x in steps),
            "max_contact_area_on_mobile_mm2": max(float(x.contact_area_on_mobile_mm2)
                                                  for x in steps),
            # per solved time point (the rows of timeseries.csv): verification.metrics compares
            # the springs, which live on M, with these
            "contact_area_on_mobile_mm2": [float(x.contact_area_on_mobile_mm2) for x in steps],
            "contact_area_on_mobile_definition": AREA_ON_MOBILE_DEFINITION,
            "final_displacement_mm": [float(v) for v in last.displacement_mm],
            "final_rotation_rad": [float(v) for v in last.rotation_rad],
            "max_force_residual_n": max(float(x.force_residual_n) for x in steps),
            "max_moment_residual_nmm": max(float(x.moment_residual_nmm) for x in steps),
            "warnings": list(self.warnings),
            "contact_area_definition": AREA_DEFINITION_NITSCHE,
            "element": s.element,
            "degree": s.degree,
            "mesh_size_mm": float(s.mesh_size_mm),
            "contact_mesh_size_mm": s.contact_mesh_size_mm,
            "mean_edge_mm": max(float(x.mean_edge_mm) for x in steps),
            "layers_through_thickness": max(int(x.layers) for x in steps),
            "newton_iterations": int(sum(x.iterations for x in steps)),
            # the inner solves: "direct" (LU) or "iterative" (Krylov; its iterations over all solves)
            "linear_solver": sorted({x.linear_solver for x in steps if x.linear_solver}),
            "krylov_iterations": int(sum(x.krylov_iterations for x in steps)),
            # per solved time point (timeseries.csv's order): its Newton steps, and on the iterative
            # path the Krylov iterations of each step (an empty list for the LU)
            "newton_iterations_per_time_point": [int(x.iterations) for x in steps],
            "krylov_iterations_per_newton_step": [[int(n) for n in x.krylov_iterations_per_step] for x in steps],
            "max_nominal_strain": max(float(x.max_nominal_strain) for x in steps),
            "nominal_strain_definition": NOMINAL_STRAIN_DEFINITION,
            "max_principal_strain": max(float(x.max_principal_strain) for x in steps),
            "model": s.model,
            "law": self.scene.cartilage.law,
            "time_points": [int(x.step) for x in steps],
            "n_time_points": int(self.n_time_points),
            **self.time_stepping_summary,
        }

    def timeseries_rows(self) -> list[dict[str, float]]:
        """timeseries.csv: the common columns (``iterations`` = Newton iterations) per solved time point."""
        return [timeseries_row(s.step, s.time_s, s.force_n, s.peak_pressure_mpa, s.mean_pressure_mpa, s.contact_area_mm2,
                               s.displacement_mm, s.rotation_rad, s.iterations, s.force_residual_n)
                for s in self.steps]

    def frames(self, positions: Sequence[int] | None = None) -> list[Frame]:
        """pressure_NNNN.vtp of the solved time points at ``positions`` (default: all): the FE contact
        surface in the reference configuration of that time point, point data pressure_mpa,
        spring_length_mm, in_contact, gap_mm, pressure_on_mobile_mpa, mobile_point_mm; cell data
        pressure_mpa, spring_length_mm, in_contact, pressure_on_mobile_mpa (module docstring)."""
        return [Frame(s.step, s.time_s, SurfaceFrame(s.points_mm, s.triangles, s.point_data, s.cell_data))
                for s in (self.steps if positions is None else [self.steps[k] for k in positions])]

    def fixed_frames(self, positions: Sequence[int] | None = None) -> list[Frame]:
        return []


def _selected_steps(steps: Sequence[int] | None, n: int) -> list[int]:
    """Sorted unique time point indices (None: all; negative ones count from the end)."""
    if steps is None:
        return list(range(n))
    expected = f"time point indices 0..{n - 1} (negative ones count from the end)"
    try:
        given = [int(i) for i in steps]
    except (TypeError, ValueError):
        raise InputError(f"{steps!r} is not a list of time point indices", key="steps", expected=expected) from None
    selected = set()
    for i in given:
        j = i + n if i < 0 else i
        if not 0 <= j < n:
            raise InputError(f"time point {i} does not exist (the scene has {n})", key="steps", expected=expected)
        selected.add(j)
    if not selected:
        raise InputError("the time point selection is empty", key="steps", expected=expected)
    return sorted(selected)


def _check_size(scene: Any, settings: FESettings, caster: RayCaster, selected: Sequence[int]):
    """Size the first selected time point's solid before meshing; refuse (InputError) a run that
    would not fit in memory (:mod:`fem_reference.sizing`). None when there is nothing to size."""
    from fem_reference.sizing import check_fits, estimate, solid_size

    if not selected:
        return None
    fe_model = FE_MODELS[settings.model]
    mask, thickness = fe_model.sizing_surface(scene, caster, scene.fixed_placement(selected[0]))
    if not mask.any():
        return None  # the model refuses this with its own message
    edge = mean_edge(scene.mobile.vertices_mm, scene.mobile.triangles[mask])
    fine_size = settings.contact_mesh_size_mm
    fine = np.zeros_like(mask)
    if fine_size is not None:  # the triangles refined further (the model's build, contact_refinement)
        f_pose = scene.fixed_placement(selected[0])
        obstacle = RigidSurface(f_pose.points(scene.fixed.vertices_mm), scene.fixed.triangles, candidates=16)
        fine = mask & contact_refinement(scene, fe_model.reach_depth_mm(scene), obstacle, fine_size).triangles(
            scene.mobile.vertices_mm, scene.mobile.triangles)
    layers = settings.layers_through_thickness or max(1, math.ceil(thickness / settings.mesh_size_mm - 1e-9))

    def size_at(size_mm: float):
        """The estimate with the size asked about: the contact's where one is given (the finer), else the mesh's."""
        coarse_mm, fine_mm = (settings.mesh_size_mm, size_mm) if fine_size is not None else (size_mm, size_mm)
        # the layers follow the mesh size, the solid's (the fine part has as many as the rest)
        cells, vertices = solid_size(int((mask & ~fine).sum()), edge, thickness, coarse_mm,
                                     settings.layers_through_thickness if fine_size is None else layers)
        fine_cells, fine_vertices = solid_size(int(fine.sum()), edge, thickness, fine_mm, layers) if fine.any() else (0, 0)
        return estimate(fe_model.bodies * (cells + fine_cells), fe_model.bodies * (vertices + fine_vertices), settings.element,
                        linear_solver=settings.linear_solver)

    asked = settings.mesh_size_mm if fine_size is None else fine_size
    size = size_at(asked)
    check_fits(size, asked, size_at, file=scene.source,
               key="mesh_size_mm (--mesh-size, or [fe] in the scene)" if fine_size is None
               else "contact_mesh_size_mm (--contact-mesh-size, or [fe] in the scene)")
    return size


def _build_geometry(scene: Any, settings: FESettings, k: int, caster: RayCaster, solid_cache: dict) -> FEGeometry:
    """The model's solid and F's triangulation (the obstacle) at time point k."""
    f_pose = scene.fixed_placement(k)
    rotation, translation = f_pose.affine()
    obstacle = RigidSurface(f_pose.points(scene.fixed.vertices_mm), scene.fixed.triangles, candidates=16)
    pose_key = (np.round(rotation, 14).tobytes(), np.round(translation, 12).tobytes())
    fe_model = FE_MODELS[settings.model]
    geom = fe_model.build(scene, settings.mesh_size_mm, settings.layers_through_thickness, caster, f_pose, obstacle, pose_key, solid_cache,
                          settings.contact_mesh_size_mm)
    if geom.mobile_points_mm is None:
        geom.mobile_points_mm = fe_model.mobile_points_mm(scene, geom.solid, contact_surface(geom.solid)[2])
    return geom


def mean_edge(points: np.ndarray, tris: np.ndarray) -> float:
    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    return float(np.mean(np.linalg.norm(points[e[:, 0]] - points[e[:, 1]], axis=1)))


# --------------------------------------------------------------------------------------------
# free rigid motions
# --------------------------------------------------------------------------------------------


def _mode_name(v: np.ndarray, names: tuple[str, str, str]) -> str:
    i = int(np.argmax(np.abs(v)))
    if abs(abs(v[i]) - 1.0) < 1e-9:
        return names[i]
    return "(" + ", ".join(f"{x:.3g}" for x in v) + ")"


def _free_modes(scene: Any, geom: FEGeometry, settings: FESettings, force: np.ndarray,
                moment: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Free translation directions (k_t, 3) and rotation axes (k_r, 3) for this time point.

    The scene's free DOFs, less the rigid motions the contact cannot resist: the contact
    stiffness of a rigid motion is estimated by sum_i A_i (w . N_i)^2 over the contact-surface
    vertices that face F and can reach it (N_i = the obstacle normal and its moment arm about
    G); motions below WEAK_MODE_RATIO of the stiffest are fixed (warning) when the load has no
    component along them, else the time point has no equilibrium (SolverError).
    """
    fixed = set(scene.fixed_dofs)
    trans = np.array([np.eye(3)[i] for i, n in enumerate(DOF_NAMES[:3]) if n not in fixed])
    rots = np.array([np.eye(3)[i] for i, n in enumerate(DOF_NAMES[3:]) if n not in fixed])
    trans = trans.reshape(-1, 3)
    rots = rots.reshape(-1, 3)
    if len(trans) == 0:
        raise InputError("the FE reference needs at least one free translation of the bone",
                           file=scene.source, key="constraints.fixed_dofs",
                           expected="at most two of tx, ty, tz fixed")
    pts, tris, _ = contact_surface(geom.solid)
    a, b, c = (pts[tris[:, i]] for i in range(3))
    cr = np.cross(b - a, c - a)
    area = 0.5 * np.linalg.norm(cr, axis=1)
    n_out = cr / np.maximum(2.0 * area, 1e-300)[:, None]
    lumped = np.zeros(len(pts))
    vnorm = np.zeros_like(pts)
    for j in range(3):
        np.add.at(lumped, tris[:, j], area / 3.0)
        np.add.at(vnorm, tris[:, j], cr)
    vnorm /= np.maximum(np.linalg.norm(vnorm, axis=1), 1e-300)[:, None]
    gap, nu = geom.obstacle.gap_and_normal(pts)
    facing = np.einsum("ij,ij->i", nu, vnorm) < -0.1
    reach = FE_MODELS[settings.model].reach(scene, gap, facing)
    if not reach.any():
        raise SolverError("no part of the FE contact surface faces the fixed body within reach")
    g = np.asarray(scene.reference_point_mm, dtype=float)
    arm = pts[reach] - g
    length = float(np.sqrt(np.mean(np.einsum("ij,ij->i", arm, arm)))) or 1.0
    rows = np.hstack([nu[reach] @ trans.T, np.cross(arm, nu[reach]) @ rots.T / length])
    w = lumped[reach]
    stiff = rows.T @ (rows * w[:, None])
    lam, vec = np.linalg.eigh(stiff)
    weak = lam <= WEAK_MODE_RATIO * max(float(lam.max()), 1e-300)
    warnings: list[str] = []
    if not weak.any():
        return trans, rots, warnings
    kt = len(trans)
    gen_load = np.concatenate([trans @ force, rots @ moment / length])
    scale = float(np.linalg.norm(np.concatenate([force, moment / length])))
    names_t, names_r = DOF_NAMES[:3], DOF_NAMES[3:]
    for v in vec[:, weak].T:
        vt, vr = trans.T @ v[:kt], rots.T @ v[kt:]
        what = (f"translation {_mode_name(vt, names_t)}" if np.linalg.norm(vr) < 1e-9 else
                f"rotation {_mode_name(vr, names_r)}" if np.linalg.norm(vt) < 1e-9 else
                "a combined translation and rotation")
        if abs(float(v @ gen_load)) > 1e-9 * max(scale, 1e-300):
            dof = (names_t[int(np.argmax(np.abs(vt)))] if np.linalg.norm(vt) >= np.linalg.norm(vr)
                   else names_r[int(np.argmax(np.abs(vr)))])
            raise SolverError(
                f"frictionless FE contact cannot resist the {what} of the bone (every contact "
                f"normal is perpendicular to it) and the load has a component along it "
                f"({float(v @ gen_load):.4g} N): no equilibrium; fix it in [constraints] "
                f"fixed_dofs (e.g. add \"{dof}\"; the constraint then carries that load)")
        if np.linalg.norm(vr) >= 1e-9 and np.linalg.norm(vt) >= 1e-9:
            raise SolverError(
                f"frictionless FE contact cannot resist a combined rigid motion "
                f"(translation {np.round(vt, 3).tolist()}, rotation {np.round(vr, 3).tolist()}): "
                "fix more DOFs in [constraints] fixed_dofs")
        warnings.append(
            f"frictionless FE contact offers no stiffness along the {what} of the bone (every "
            "contact normal is perpendicular to it; the discrete springs along M's normals may "
            "resist it): fixed in the FE, the load has no component along it")
    keep = vec[:, ~weak]
    # the kept modes split into pure translations and pure rotations (mixed weak modes refused)
    t_span = keep[:kt]
    r_span = keep[kt:]
    trans = _orthonormal_rows(trans.T @ t_span)
    rots = _orthonormal_rows(rots.T @ r_span) if len(rots) else rots
    if len(trans) == 0:
        raise SolverError("frictionless FE contact resists no free translation of the bone")
    return trans, rots, warnings


def _orthonormal_rows(cols: np.ndarray) -> np.ndarray:
    """Orthonormal basis (rows) of the span of the columns, axis-aligned when it can be."""
    if cols.size == 0:
        return np.zeros((0, 3))
    u, s, _ = np.linalg.svd(cols, full_matrices=False)
    basis = u[:, s > 1e-9 * max(float(s.max()), 1e-300)].T
    # prefer coordinate axes when the span is spanned by them
    axes = [np.eye(3)[i] for i in range(3)
            if np.linalg.norm(basis @ np.eye(3)[i]) > 1 - 1e-9]
    if len(axes) == len(basis):
        return np.array(axes).reshape(-1, 3)
    return basis


# --------------------------------------------------------------------------------------------
# the run
# --------------------------------------------------------------------------------------------


def run_scene(scene: Any, *, model: str | None = None, mesh_size_mm: float | None = None,
              degree: int | None = None, element: str | None = None,
              linear_solver: str | None = None,
              steps: Sequence[int] | None = None, out_dir: str | Path | None = None,
              layers_through_thickness: int | None = None, contact_mesh_size_mm: float | None = None, comm: Any = None,
              progress: Callable[[int], None] | None = None, overwrite: bool = False,
              on_size: Callable[[Any], None] | None = None, provenance: Provenance | None = None,
              solve_progress: SolveProgress | None = None) -> FERunResult:
    """Solve the FE reference of ``scene`` (an :class:`edem.scene.Scene`) at the selected time
    points and, with ``out_dir``, write the result directory (docs/result-format.md) (rank 0 only).

    Settings come from the arguments, then the scene's ``[fe]`` table (model, mesh_size_mm,
    degree, element, layers_through_thickness, contact_mesh_size_mm, linear_solver), then the defaults
    (:func:`resolve_settings`).
    ``steps``: None (all) or time point indices (negative ones count from the end).
    ``progress(k)`` is called after each solved time point. ``overwrite``: replace an existing
    result directory at ``out_dir``; ``provenance`` (:func:`edem.resultdir.provenance`) is written
    with it.
    ``on_size(size)`` is called once, with the :class:`fem_reference.sizing.FESize` estimate, after
    the run was sized and found to fit. ``solve_progress``: progress lines from inside each solve
    (:mod:`fem_reference.progress`), labelled with the time point; rank 0's argument decides for
    every rank (the others may pass None).

    Raises InputError on bad settings and SolverError (FEConvergenceError for a Newton failure)
    naming the time point when one has no solution.
    """
    from fem_reference.sizing import peak_memory_bytes, reset_peak_memory

    started = time.perf_counter()
    reset_peak_memory()
    settings = resolve_settings(scene, model=model, mesh_size_mm=mesh_size_mm, degree=degree,
                                element=element, layers_through_thickness=layers_through_thickness,
                                linear_solver=linear_solver, contact_mesh_size_mm=contact_mesh_size_mm)
    n_times = len(scene.load.time_s)
    selected = _selected_steps(steps, n_times)
    try:
        mods = fe_modules()
    except ImportError as exc:
        raise InputError(f"the FE reference needs dolfinx ({exc})",
                           expected="the `fe` extra: pip install -e '.[fe]'") from None
    MPI = mods["MPI"]
    comm = MPI.COMM_WORLD if comm is None else comm

    caster = RayCaster(scene.fixed.vertices_mm, scene.fixed.triangles)
    loads = scene.applied_loads()
    warnings: list[str] = list(scene.warnings)
    if scene.ligaments:
        warnings.append(f"the FE reference does not model ligaments: the scene's "
                        f"{len(scene.ligaments)} ligament(s) are left out")
    if scene.biphasic is not None and settings.biphasic is None:
        warnings.append('[biphasic] is read only with [fe] material = "biphasic": this FE run is not biphasic')
    if settings.biphasic is not None and scene.viscoelastic is not None:
        warnings.append("the biphasic FE creeps by its fluid flow: it does not read [viscoelastic] (the springs' tau)")
    stepping = time_stepping(scene, settings)
    warnings += stepping.start_warnings(loads[0, :3])
    solved = stepping.time_points(selected)
    if scene.cartilage.shear_modulus_mpa:
        warnings.append("cartilage.shear_modulus_mpa is ignored by the FE reference (the "
                        "continuum has its own shear stiffness; the contact is frictionless)")
    size = _check_size(scene, settings, caster, selected)
    if on_size is not None and size is not None:
        on_size(size)
    if not comm.bcast(solve_progress is not None, root=0):
        solve_progress = None  # rank 0 decides: the monitors assemble on every rank or on none
    elif solve_progress is None:
        solve_progress = SolveProgress(lambda line: None)
    step_log: list[tuple[str, str]] = []
    solid_cache: dict = {}
    mesh_cache: dict = {}
    results: list[FEStepResult] = []
    for k in solved:
        t = float(scene.load.time_s[k])
        where = f"time point {k} (t = {t:g} s)"
        clock = time.perf_counter()
        try:
            geom = _build_geometry(scene, settings, k, caster, solid_cache)
        except (SolverError, InputError) as exc:
            exc.args = (f"{where}: {exc}",)
            raise
        step_warnings = list(geom.warnings)
        force, moment = loads[k, :3].astype(float), loads[k, 3:].astype(float)
        point = TimePoint(k, t, where, geom, force, comm, solve_progress, mesh_cache.get("mesh"), mesh_cache.get("key"))
        carried = False  # a load the constraints carry alone
        if np.any(force):
            try:
                trans, rots, mode_warnings = _free_modes(scene, geom, settings, force, moment)
            except (SolverError, InputError) as exc:
                exc.args = (f"{where}: {exc}",)
                raise
            step_warnings += mode_warnings
            carried = np.linalg.norm(trans @ force) == 0.0 and (len(rots) == 0 or np.linalg.norm(rots @ moment) == 0.0)
        if carried or not np.any(force):
            translation, rotation, what = stepping.unloaded(point)
            step_warnings.append("the load has no component along the free DOFs: carried by the constraints (zero pressure)"
                                 if carried else f"no force: {what} (zero pressure)")
            results.append(_zero_step(k, t, force, moment, geom, settings, clock, translation, rotation))
            results[-1].warnings = step_warnings
            _add(step_log, step_warnings, where)
            if progress is not None:
                progress(k)
            continue
        fe_model = FE_MODELS[settings.model]
        mesh_key = geom.key if fe_model.mesh_follows_pose else geom.key[0]
        if mesh_cache.get("key") != mesh_key:
            mesh_cache.clear()
            mesh, cell_tags, facet_tags = geom.solid.to_dolfinx(comm)
            mesh_cache.update(key=mesh_key, mesh=FEMesh(mesh, facet_tags, cell_tags))
        point.mesh, point.mesh_key = mesh_cache["mesh"], mesh_key
        problem = FEContactProblem(
            mesh=mesh_cache["mesh"],
            youngs_modulus_mpa=float(scene.cartilage.youngs_modulus_mpa),
            poissons_ratio=float(scene.cartilage.poissons_ratio),
            obstacle=geom.obstacle,
            force_n=force,
            element=settings.element,
            free_dofs=[tuple(r) for r in trans],
            free_rotations=[tuple(r) for r in rots] if len(rots) else None,
            moment_nmm=moment,
            reference_point_mm=np.asarray(scene.reference_point_mm, dtype=float),
            strain_warning=STRAIN_WARNING,
            solver=SolverOptions(linear_solver=settings.linear_solver),
        )
        stepping.prepare(point, problem)
        try:
            res = stepping.solve(point, problem)
        except (SolverError, InputError) as exc:  # FEConvergenceError too
            exc.args = (f"{where}: {exc}",)
            raise
        except Exception as exc:
            raise SolverError(f"{where}: the FE solve failed: {type(exc).__name__}: {exc}"
                                ) from None
        step_warnings += [w for w in res.warnings if not w.startswith("max nominal strain")]
        results.append(_step_result(k, t, force, moment, geom, settings, res, clock, scene))
        res.fields = None  # the dolfinx objects of this solve are no longer needed
        step_warnings += _beyond_refinement(geom, results[-1], settings)
        if results[-1].max_nominal_strain > STRAIN_WARNING:
            step_warnings.append(
                f"nominal strain {results[-1].max_nominal_strain:.3f} (compression / thickness) "
                f"exceeds {STRAIN_WARNING:.2f}: small-strain elasticity no longer holds")
        results[-1].warnings = step_warnings
        _add(step_log, step_warnings, where)
        if progress is not None:
            progress(k)
    results = [r for r in results if r.step in selected]
    run = FERunResult(scene, settings, results, time.perf_counter() - started,
                      _merge_warnings(warnings, step_log), n_times, None, comm.rank,
                      peak_memory_bytes(), stepping.summary())
    if out_dir is not None:
        run.out_dir = Path(out_dir)
        write_run(run, run.out_dir, overwrite=overwrite, provenance=provenance, comm=comm)  # rank 0 writes
    return run


def world_rank() -> int:
    """Rank in MPI.COMM_WORLD (0 without the FE stack)."""
    try:
        return int(fe_modules()["MPI"].COMM_WORLD.rank)
    except ImportError:
        return 0


def _beyond_refinement(geom: FEGeometry, step: FEStepResult, settings: FESettings) -> list[str]:
    """A warning where the contact reaches beyond the region refined to the contact mesh size
    (judged at the first time point's pose; there the mesh is the coarser one), else none."""
    if geom.refinement is None:
        return []
    touching = step.point_data["in_contact"].astype(bool)
    beyond = touching & ~geom.refinement.reaches(geom.mobile_points_mm)
    if not beyond.any():
        return []
    return [f"the contact reaches {int(beyond.sum())} of its {int(touching.sum())} contact-face nodes beyond the region refined to "
            f"{settings.contact_mesh_size_mm:g} mm (where it could reach at the first time point's pose): the mesh there is "
            f"{settings.mesh_size_mm:g} mm (a finer mesh_size_mm, or a run per pose)"]


def _add(warnings: list[tuple[str, str]], step_warnings: list[str], where: str) -> None:
    warnings.extend((where, w) for w in step_warnings)


def _merge_warnings(general: list[str], per_step: list[tuple[str, str]]) -> list[str]:
    """One line per kind of warning (numbers ignored): the first occurrence, and how many other
    time points had it."""
    order: dict[str, list[str]] = {}
    for where, w in per_step:
        order.setdefault(re.sub(r"\d+(\.\d+)?(e[-+]?\d+)?", "#", w), []).append(f"{where}: {w}")
    out = list(general)
    for texts in order.values():
        extra = len(texts) - 1
        out.append(texts[0] + (f" (and at {extra} other time point{'s' * (extra > 1)})"
                               if extra else ""))
    return out


def _surface_data(geom: FEGeometry, settings: FESettings, scene: Any,
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                             np.ndarray]:
    """Contact-surface points, triangles, local spring length (slab: thickness; layer:
    thickness + initial gap), initial gap, obstacle normal and undeformed thickness per point."""
    pts, tris, used = contact_surface(geom.solid)
    gap, nu = geom.obstacle.gap_and_normal(pts)
    fe_model = FE_MODELS[settings.model]
    thickness = fe_model.thickness_mm(scene, geom.solid, used, pts)
    length = fe_model.spring_length_mm(thickness, gap)
    return pts, tris, length, gap, nu, thickness


def _mobile_mapping(geom: FEGeometry) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the contact surface stands on M: per contact-surface point the point of M's scene
    surface its column crosses (the model's :meth:`~fem_reference.models.FEModel.mobile_points_mm`),
    per point and per facet the area ratio (contact face / M) of the columns (lumped at the
    points): a pressure times this ratio is the force per area of M, as the springs carry it."""
    pts, tris, _ = contact_surface(geom.solid)
    on_mobile = geom.mobile_points_mm

    def areas(x: np.ndarray) -> np.ndarray:
        return triangle_areas(x[tris[:, 0]], x[tris[:, 1]], x[tris[:, 2]])

    a_top, a_mobile = areas(pts), areas(on_mobile)
    lumped_top, lumped_mobile = np.zeros(len(pts)), np.zeros(len(pts))
    for j in range(3):
        np.add.at(lumped_top, tris[:, j], a_top / 3.0)
        np.add.at(lumped_mobile, tris[:, j], a_mobile / 3.0)
    return on_mobile, lumped_top / lumped_mobile, a_top / a_mobile


def _zero_step(k: int, t: float, force: np.ndarray, moment: np.ndarray, geom: FEGeometry,
               settings: FESettings, clock: float, displacement_mm: np.ndarray,
               rotation_rad: np.ndarray) -> FEStepResult:
    pts, tris, used = contact_surface(geom.solid)
    z = np.zeros(len(pts))
    zc = np.zeros(len(tris))
    gap, _ = geom.obstacle.gap_and_normal(pts)
    return FEStepResult(
        step=k, time_s=t, force_n=force, moment_nmm=moment,
        displacement_mm=np.asarray(displacement_mm, float), rotation_rad=np.asarray(rotation_rad, float),
        peak_pressure_mpa=0.0, mean_pressure_mpa=0.0,
        contact_area_mm2=0.0, contact_area_on_mobile_mm2=0.0, iterations=0,
        force_residual_n=0.0, moment_residual_nmm=0.0,
        n_dofs=0, wall_time_s=time.perf_counter() - clock, max_nominal_strain=0.0,
        max_principal_strain=0.0,
        contact_force_n=np.zeros(3), constraint_force_n=-force,
        points_mm=pts, triangles=tris,
        point_data={"pressure_mpa": z, "spring_length_mm": z.copy(),
                    "in_contact": z.astype(np.int8), "gap_mm": gap,
                    "pressure_on_mobile_mpa": z.copy(),
                    "mobile_point_mm": geom.mobile_points_mm},
        cell_data={"pressure_mpa": zc, "spring_length_mm": zc.copy(),
                   "in_contact": zc.astype(np.int8), "pressure_on_mobile_mpa": zc.copy()},
        mean_edge_mm=mean_edge(pts, tris), layers=int(geom.solid.layer.max()))


def _area_on_mobile(res: Any, geom: FEGeometry) -> float:
    """The Nitsche contact-area integral with each contact facet weighted by (area of M's
    triangle under it, :func:`_mobile_mapping`) / (its own area): the contact area measured on M."""
    m = fe_modules()
    fem, ufl, dmesh = m["fem"], m["ufl"], m["dolfinx"].mesh
    s, pressure = res.fields["setup"], res.fields["pressure"]
    mesh = s.mesh
    solid = geom.solid
    _, tris, used = contact_surface(solid)
    top = used[tris]  # solid point indices of the contact triangles
    x = solid.points_mm
    ratio_of = 1.0 / _mobile_mapping(geom)[2]
    V0 = fem.functionspace(mesh, ("DG", 0))
    w = fem.Function(V0)
    facets = s.contact_facets
    if len(facets):
        geo = dmesh.entities_to_geometry(mesh, 2, facets, False)
        centroids = mesh.geometry.x[geo].mean(axis=1)
        dist, idx = cKDTree(x[top].mean(axis=1)).query(centroids)
        size = float(np.ptp(x, axis=0).max()) or 1.0
        if float(dist.max()) > 1e-8 * size:
            raise SolverError("the FE contact facets do not match the solid's contact face")
        mesh.topology.create_connectivity(2, 3)
        f2c = mesh.topology.connectivity(2, 3)
        cells = np.array([f2c.links(f)[0] for f in facets], dtype=np.int32)
        dofs = np.array([V0.dofmap.cell_dofs(c)[0] for c in cells])
        w.x.array[dofs] = ratio_of[idx]
    peak = float(res.peak_pressure_mpa)
    ptol = fem.Constant(mesh, 1e-8 * max(peak, 1e-300))
    ind = ufl.conditional(ufl.gt(pressure, ptol), 1.0, 0.0)
    return s.scalar(fem.form(ind * w * s.ds_c))


def _step_result(k: int, t: float, force: np.ndarray, moment: np.ndarray, geom: FEGeometry,
                 settings: FESettings, res: Any, clock: float, scene: Any) -> FEStepResult:
    pts, tris, length, gap, nu, thickness = _surface_data(geom, settings, scene)
    area_on_mobile = _area_on_mobile(res, geom)
    on_mobile, ratio_point, ratio_cell = _mobile_mapping(geom)
    xs = np.asarray(res.contact_points_mm).reshape(-1, 3)
    dist, idx = cKDTree(xs).query(pts)
    size = float(np.ptp(pts, axis=0).max()) or 1.0
    if len(xs) != len(pts) or float(dist.max()) > 1e-8 * size:
        raise SolverError(
            f"time point {k}: the FE contact-surface nodes do not match the solid's contact face "
            f"({len(xs)} nodes for {len(pts)} vertices, farthest {float(dist.max()):.3g} mm)")
    p = np.clip(np.asarray(res.contact_pressure_mpa)[idx], 0.0, None)
    tol = 1e-8 * max(float(res.peak_pressure_mpa), 1e-300)
    p_cell = p[tris].mean(axis=1)
    length_cell = length[tris].mean(axis=1)
    for name, value in (("pressure", p), ("displacement", res.bone_displacement_mm),
                        ("rotation", res.bone_rotation_rad)):
        if not np.all(np.isfinite(value)):
            raise SolverError(f"time point {k}: the FE {name} is not finite")
    rigid = (res.bone_displacement_mm[None, :]
             + np.cross(res.bone_rotation_rad, pts - np.asarray(scene.reference_point_mm)))
    approach = -np.einsum("ij,ij->i", rigid, nu) - gap
    contact = p > tol
    # A bone pressed farther than the cartilage is thick anywhere has gone through it: the linear
    # solve still balances (a load 1e12 times too large gave 7e10 mm), but not on this geometry.
    deepest = float(np.max(approach[contact], initial=0.0))
    if deepest > float(thickness.max()):
        raise SolverError(
            f"time point {k}: the bone moves {deepest:.3g} mm into the cartilage, more than its greatest thickness "
            f"{float(thickness.max()):.3g} mm: it has gone through it, where small-strain FE does not hold; check the load's units and scale")
    nominal = float(np.max(approach[contact] / thickness[contact], initial=0.0))
    return FEStepResult(
        step=k, time_s=t, force_n=force, moment_nmm=moment,
        displacement_mm=np.asarray(res.bone_displacement_mm, dtype=float),
        rotation_rad=np.asarray(res.bone_rotation_rad, dtype=float),
        peak_pressure_mpa=float(res.peak_pressure_mpa),
        mean_pressure_mpa=float(res.mean_pressure_mpa),
        contact_area_mm2=float(res.contact_area_mm2),
        contact_area_on_mobile_mm2=float(area_on_mobile),
        iterations=int(res.newton_iterations),
        linear_solver=res.linear_solver, krylov_iterations=int(res.krylov_iterations),
        krylov_iterations_per_step=list(res.krylov_iterations_per_step),
        force_residual_n=float(res.force_residual_n),
        moment_residual_nmm=float(res.moment_residual_nmm),
        n_dofs=int(res.n_dofs),
        wall_time_s=time.perf_counter() - clock,
        max_nominal_strain=max(nominal, 0.0),
        max_principal_strain=float(res.max_nominal_strain),
        contact_force_n=np.asarray(res.contact_force_n, dtype=float),
        constraint_force_n=np.asarray(res.constraint_force_n, dtype=float),
        points_mm=pts, triangles=tris,
        point_data={"pressure_mpa": p, "spring_length_mm": length,
                    "in_contact": (p > tol).astype(np.int8), "gap_mm": gap,
                    "pressure_on_mobile_mpa": p * ratio_point, "mobile_point_mm": on_mobile},
        cell_data={"pressure_mpa": p_cell, "spring_length_mm": length_cell,
                   "in_contact": (p_cell > tol).astype(np.int8),
                   "pressure_on_mobile_mpa": p_cell * ratio_cell},
        mean_edge_mm=mean_edge(pts, tris), layers=int(geom.solid.layer.max()))
