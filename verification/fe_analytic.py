"""The FE reference against its closed forms (docs/method.md#6-the-fe-reference-and-its-discrete-twins): problems that do not go through scenes.

Two FE problems of :mod:`fem_reference` (its core API: meshes, :class:`FEContactProblem`,
:func:`solve_contact`), set up as the core's own tests set them up (tests/fem_reference), and
their closed forms (:mod:`fem_reference.closed_forms`), each written as a docs/result-format.md result
directory so that a campaign case compares them like any two sides
(:func:`verification.metrics.compare_result_dirs`):

* ``hertz-line``: a rigid cylinder, R = 20 mm, on an elastic block 20 mm wide (half model,
  symmetry x = 0) and 20 mm thick bonded to a rigid base, plane strain by a one-element slice,
  loaded for a Hertz half-width a = 1 mm (P' = pi a^2 E* / (4 R)): p0 = 2 P' / (pi a),
  p(x) = p0 sqrt(1 - x^2/a^2); contact area of the half model = a x slice. Mesh size = element
  size at the contact (and the slice thickness), 10x that far away (tests/fem_reference/fe_cases).
* ``confined-compression``: a slab 10 x 8 x 2 mm bonded at z = 0, lateral faces on rollers,
  120 N on its bone against a rigid plane: p = F / A and d = p h / E' (p = E' d / h).

Two deformable layers (:mod:`fem_reference.two_body`, docs/method.md#two-deformable-layers):

* ``hertz-cylinders``: two equal elastic cylinders, R = 20 mm, each a quarter disk bonded on its
  diameter (half model, symmetry x = 0), the lower one the mirror image of the upper, plane
  strain by a one-element slice, loaded for a = 1 mm with E* = E / (2 (1 - nu^2)), R* = R / 2;
  contact area of the half model a x slice (M's contact face, the upper cylinder's arc).
* ``two-layer-confined``: M's layer 2 mm (the cartilage) on F's 1 mm (E 5 MPa, nu 0.3), 10 x 8 mm,
  lateral faces on rollers, 120 N: p = F / A, d = p (h_M / E'_M + h_F / E'_F).

Cartilage of docs/references.md#the-thesiss-figures (E = 10.35 MPa, nu = 0.42). Options of a case: ``mesh_size_mm`` and
``element`` (P1, P2, TH; default P2). dolfinx is imported only when an FE problem is solved.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from geometries.errors import InputError
from edem.resultdir import write_static_result_dir

MATERIAL = {"youngs_modulus_mpa": 10.35, "poissons_ratio": 0.42}  # docs/references.md#the-thesiss-figures cartilage


@dataclass(frozen=True)
class HertzSetup:
    """Rigid cylinder on a thick bonded block (the set-up of tests/fem_reference/fe_cases.py)."""

    radius_mm: float = 20.0
    half_width_mm: float = 1.0  # the Hertz half-width the load is chosen for
    block_mm: float = 20.0  # half width and thickness of the block (20 a)
    far_factor: float = 10.0  # element size far from the contact = far_factor x mesh size
    fine_radius_factor: float = 1.5  # the contact size holds within 1.5 a of the first touch
    coarse_radius_mm: float = 15.0

    def reference(self):
        from fem_reference import closed_forms as cf

        return cf.HertzLine.for_half_width(self.half_width_mm, self.radius_mm, **MATERIAL)


@dataclass(frozen=True)
class ConfinedSetup:
    """A laterally confined slab under a rigid plane (tests/fem_reference/test_fe_confined_compression.py)."""

    lx_mm: float = 10.0
    ly_mm: float = 8.0
    thickness_mm: float = 2.0
    load_n: float = 120.0  # p = 1.5 MPa

    def divisions(self, mesh_size_mm: float) -> tuple[int, int, int]:
        return tuple(max(1, int(round(length / mesh_size_mm))) for length in (self.lx_mm, self.ly_mm, self.thickness_mm))  # type: ignore[return-value]


@dataclass(frozen=True)
class CylindersSetup:
    """Two equal elastic cylinders (fem_reference.meshes.hertz_cylinder and mirrored_pair)."""

    radius_mm: float = 20.0
    half_width_mm: float = 1.0
    far_factor: float = 10.0  # element size 15 mm from the contact = far_factor x the contact size
    fine_radius_factor: float = 1.5  # the contact size holds within 1.5 a of the first touch
    coarse_radius_mm: float = 15.0
    contact_extent_mm: float = 5.0  # the arc tagged as contact face (5 a)

    def reference(self):
        from fem_reference import closed_forms as cf

        return cf.HertzLine.for_half_width(self.half_width_mm, self.radius_mm, **MATERIAL, other_radius_mm=self.radius_mm,
                                           other_youngs_modulus_mpa=MATERIAL["youngs_modulus_mpa"],
                                           other_poissons_ratio=MATERIAL["poissons_ratio"])


@dataclass(frozen=True)
class TwoLayerSetup:
    """M's layer on F's, both confined (fem_reference.meshes.two_layer_stack)."""

    lx_mm: float = 10.0
    ly_mm: float = 8.0
    mobile_thickness_mm: float = 2.0
    fixed_thickness_mm: float = 1.0
    fixed_material: tuple[float, float] = (5.0, 0.3)  # E (MPa), nu of F's layer
    load_n: float = 120.0  # p = 1.5 MPa

    def divisions(self, mesh_size_mm: float) -> tuple[tuple[int, int], tuple[int, int]]:
        """(in-plane squares, element layers of M's and F's)."""
        def n(length: float) -> int:
            return max(1, int(round(length / mesh_size_mm)))

        return (n(self.lx_mm), n(self.ly_mm)), (n(self.mobile_thickness_mm), n(self.fixed_thickness_mm))

    def approach_mm(self) -> float:
        """d = p (h_M / E'_M + h_F / E'_F)."""
        from fem_reference import closed_forms as cf

        p = self.load_n / (self.lx_mm * self.ly_mm)
        return p * (self.mobile_thickness_mm / cf.confined_modulus(MATERIAL["youngs_modulus_mpa"], MATERIAL["poissons_ratio"])
                    + self.fixed_thickness_mm / cf.confined_modulus(*self.fixed_material))


HERTZ = HertzSetup()
CONFINED = ConfinedSetup()
CYLINDERS = CylindersSetup()
TWO_LAYERS = TwoLayerSetup()
FE_PROBLEMS: dict[str, str] = {
    "hertz-line": "Hertz line contact: rigid cylinder R 20 mm on a thick bonded block, a = 1 mm",
    "confined-compression": "confined compression of a 10 x 8 x 2 mm slab, 120 N: p = E' d / h",
    "hertz-cylinders": "Hertz line contact of two equal elastic cylinders R 20 mm (both deformable), a = 1 mm",
    "two-layer-confined": "two confined layers in series, 2 mm (E 10.35, nu 0.42) on 1 mm (E 5, nu 0.3), 10 x 8 mm, 120 N: "
                          "d = p (h_M / E'_M + h_F / E'_F)",
}
#: the problems whose contact half-width is measured against Hertz
HERTZ_PROBLEMS = ("hertz-line", "hertz-cylinders")
ELEMENTS = ("P1", "P2", "TH")


def _options(name: str, options: dict[str, Any]) -> tuple[float, str]:
    if name not in FE_PROBLEMS:
        raise InputError(f"unknown FE problem '{name}'", key="sides", expected="one of " + ", ".join(FE_PROBLEMS))
    size = options.get("mesh_size_mm")
    if not isinstance(size, (int, float)) or not size > 0:
        raise InputError(f"mesh_size_mm = {size!r}", key="options.mesh_size_mm", expected="an element size in mm (> 0)")
    element = options.get("element", "P2")
    if element not in ELEMENTS:
        raise InputError(f"element = {element!r}", key="options.element", expected="one of " + ", ".join(ELEMENTS))
    return float(size), str(element)


def _planar_triangles(points_2d: np.ndarray) -> np.ndarray:
    """Delaunay triangles of points on a planar (convex, rectangular) face, degenerate ones dropped."""
    from scipy.spatial import Delaunay

    tris = Delaunay(points_2d).simplices.astype(np.int64)
    a, b, c = (points_2d[tris[:, i]] for i in range(3))
    area = 0.5 * np.abs((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
    return tris[area > 1e-12 * float(np.ptp(points_2d, axis=0).prod())]


def _surface_arrays(points: np.ndarray, pressure: np.ndarray, triangles: np.ndarray) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    cells = pressure[triangles].mean(axis=1)
    contact = (cells > 1e-8 * max(float(pressure.max(initial=0.0)), 1e-300)).astype(np.int8)
    return {"pressure_mpa": pressure}, {"pressure_mpa": cells, "in_contact": contact}


def _comm():
    import dolfinx_solver  # noqa: F401  (the wheel wants it imported before dolfinx / mpi4py)
    from mpi4py import MPI

    return MPI.COMM_SELF  # one process per case: the runner parallelises over cases


# ---------------------------------------------------------------------------------------------
# FE side


def _two_body_problem(solid: Any, comm: Any, element: str, fixed_material: tuple[float, float], force_n: tuple):
    """M's layer (the cartilage of :data:`MATERIAL`) against F's deformable one (``fixed_material``)
    of a paired solid, lateral / symmetry faces on rollers (tags 4, 5)."""
    from fem_reference import FEContactProblem, FEMesh, Roller
    from fem_reference.problem import DeformableCounterpart

    mesh, cell_tags, facet_tags = solid.to_dolfinx(comm)
    return FEContactProblem(
        mesh=FEMesh(mesh, facet_tags, cell_tags), element=element, force_n=force_n, rollers=(Roller(4, "x"), Roller(5, "y")),
        obstacle=DeformableCounterpart.from_solid(solid, *fixed_material), **MATERIAL)


def solve_fe_problem(name: str, options: dict[str, Any]):
    """(FEContactResult, setup numbers) of the named FE problem at the options' mesh size."""
    size, element = _options(name, options)
    from fem_reference import FEContactProblem, RigidCylinder, RigidPlane, Roller, meshes, solve_contact

    comm = _comm()
    if name == "hertz-line":
        ref = HERTZ.reference()
        mesh = meshes.hertz_block(
            comm, width=HERTZ.block_mm, height=HERTZ.block_mm, slice_thickness=size, size_contact=size,
            size_far=HERTZ.far_factor * size, fine_radius=HERTZ.fine_radius_factor * HERTZ.half_width_mm,
            coarse_radius=HERTZ.coarse_radius_mm,
        )
        problem = FEContactProblem(
            mesh=mesh, element=element, youngs_modulus_mpa=MATERIAL["youngs_modulus_mpa"], poissons_ratio=MATERIAL["poissons_ratio"],
            obstacle=RigidCylinder((0.0, 0.0, HERTZ.block_mm + HERTZ.radius_mm), (0.0, 1.0, 0.0), HERTZ.radius_mm),
            force_n=(0.0, 0.0, ref.load_per_length_n_per_mm * size / 2.0),  # half model, slice `size` thick
            rollers=(Roller(4, "x"), Roller(5, "y")),
        )
        setup = {"slice_thickness_mm": size, "load_per_length_n_per_mm": ref.load_per_length_n_per_mm}
    elif name == "hertz-cylinders":
        ref = CYLINDERS.reference()
        upper = meshes.hertz_cylinder(
            comm, radius=CYLINDERS.radius_mm, slice_thickness=size, size_contact=size, size_far=CYLINDERS.far_factor * size,
            fine_radius=CYLINDERS.fine_radius_factor * CYLINDERS.half_width_mm, coarse_radius=CYLINDERS.coarse_radius_mm,
            contact_extent=CYLINDERS.contact_extent_mm)
        problem = _two_body_problem(
            meshes.mirrored_pair(upper), comm, element, (MATERIAL["youngs_modulus_mpa"], MATERIAL["poissons_ratio"]),
            force_n=(0.0, 0.0, -ref.load_per_length_n_per_mm * size / 2.0))  # the upper one pressed down
        setup = {"slice_thickness_mm": size, "load_per_length_n_per_mm": ref.load_per_length_n_per_mm}
    elif name == "two-layer-confined":
        squares, layers = TWO_LAYERS.divisions(size)
        solid = meshes.two_layer_stack(TWO_LAYERS.lx_mm, TWO_LAYERS.ly_mm, TWO_LAYERS.mobile_thickness_mm, TWO_LAYERS.fixed_thickness_mm,
                                       squares, layers)
        problem = _two_body_problem(solid, comm, element, TWO_LAYERS.fixed_material, force_n=(0.0, 0.0, -TWO_LAYERS.load_n))
        setup = {"divisions": list(squares), "layers": list(layers)}
    else:
        mesh = meshes.box_slab(comm, CONFINED.lx_mm, CONFINED.ly_mm, CONFINED.thickness_mm, CONFINED.divisions(size), confined=True)
        problem = FEContactProblem(
            mesh=mesh, element=element, youngs_modulus_mpa=MATERIAL["youngs_modulus_mpa"], poissons_ratio=MATERIAL["poissons_ratio"],
            obstacle=RigidPlane((0.0, 0.0, CONFINED.thickness_mm), (0.0, 0.0, -1.0)),
            force_n=(0.0, 0.0, CONFINED.load_n),
            rollers=(Roller(4, "x"), Roller(5, "y")),
        )
        setup = {"divisions": list(CONFINED.divisions(size))}
    return solve_contact(problem, comm, keep_fields=False), setup


def run_fe_problem(name: str, out_dir: str | Path, options: dict[str, Any]) -> Path:
    """Solve the named FE problem and write its result directory (docs/result-format.md) (nodal pressure on the contact face)."""
    from fem_reference import closed_forms as cf

    start = time.perf_counter()
    size, element = _options(name, options)
    result, setup = solve_fe_problem(name, options)
    points, first = np.unique(np.asarray(result.contact_points_mm, dtype=np.float64), axis=0, return_index=True)
    pressure = np.asarray(result.contact_pressure_mpa, dtype=np.float64)[first]
    triangles = _planar_triangles(points[:, :2])  # every contact face is a graph z(x, y)
    point_data, cell_data = _surface_arrays(points, pressure, triangles)
    extra: dict[str, Any] = {}
    if name in HERTZ_PROBLEMS:
        extra["half_width_mm"] = result.contact_area_mm2 / setup["slice_thickness_mm"]
        try:
            extra["half_width_fit_mm"], extra["peak_fit_mpa"] = cf.fit_elliptic_half_width(points[:, 0], pressure)
        except ValueError as exc:
            extra["half_width_fit_error"] = str(exc)
    summary = {
        "scene": f"fe-problem:{name}",
        "method": f"fe-{result.method}",
        "n_dofs": int(result.n_dofs),
        "wall_time_s": time.perf_counter() - start,
        "solve_wall_time_s": float(result.wall_time_s),
        "warnings": list(result.warnings),
        "fe_problem": {
            "name": name,
            "description": FE_PROBLEMS[name],
            "mesh_size_mm": size,
            "element": result.element,
            "newton_iterations": int(result.newton_iterations),
            "converged_reason": str(result.converged_reason),
            "relative_force_residual": float(result.relative_force_residual),
            "max_nominal_strain": float(result.max_nominal_strain),
            "contact_area_definition": result.contact_area_definition,
            **setup,
            **extra,
        },
    }
    return write_static_result_dir(
        out_dir, summary=summary, force_n=result.applied_force_n, displacement_mm=result.bone_displacement_mm,
        peak_pressure_mpa=result.peak_pressure_mpa, mean_pressure_mpa=result.mean_pressure_mpa, contact_area_mm2=result.contact_area_mm2,
        points_mm=points, triangles=triangles, point_data=point_data, cell_data=cell_data,
        iterations=result.newton_iterations, force_residual_n=result.force_residual_n,
    )


# ---------------------------------------------------------------------------------------------
# Closed-form side


def write_exact_result(name: str, out_dir: str | Path, options: dict[str, Any]) -> Path:
    """The closed form of the named FE problem as a result directory (docs/result-format.md) (numpy only).

    Its surface is the FE problem's contact face, finely gridded, with the exact pressure at the
    nodes (point data: the metrics interpolate it at the FE's points). Hertz gives no rigid
    approach on a finite block: its displacement is written as 0 and marked so in the summary.
    """
    from fem_reference import closed_forms as cf

    start = time.perf_counter()
    size, _ = _options(name, options)
    e, nu = MATERIAL["youngs_modulus_mpa"], MATERIAL["poissons_ratio"]
    if name in HERTZ_PROBLEMS:
        ref = (HERTZ if name == "hertz-line" else CYLINDERS).reference()
        a = ref.half_width_mm
        extent = HERTZ.block_mm if name == "hertz-line" else CYLINDERS.contact_extent_mm
        xs = np.unique(np.concatenate([np.linspace(0.0, 1.5 * a, 3001), np.linspace(1.5 * a, extent, 201)]))
        ys = np.array([0.0, size])
        force = np.array([0.0, 0.0, ref.load_per_length_n_per_mm * size / 2.0])
        peak, area = ref.peak_pressure_mpa, a * size
        mean = force[2] / area  # = pi p0 / 4
        disp = np.zeros(3)
        if name == "hertz-line":
            z = HERTZ.block_mm
        else:  # M's contact face: the upper cylinder's arc, pressed down
            force = -force
            z = lambda x: CYLINDERS.radius_mm - np.sqrt(CYLINDERS.radius_mm**2 - x**2)  # noqa: E731
        exact = {"half_width_mm": a, "load_per_length_n_per_mm": ref.load_per_length_n_per_mm, "contact_modulus_mpa": ref.contact_modulus_mpa,
                 "formula": "a = sqrt(4 P' R / (pi E*)), p0 = 2 P' / (pi a), p = p0 sqrt(1 - x^2/a^2)",
                 "displacement": "no closed form (the approach depends on the finite block): written as 0, not compared"}
        pressure_of = ref.pressure_mpa
    elif name == "two-layer-confined":
        setup = TWO_LAYERS
        area = setup.lx_mm * setup.ly_mm
        force = np.array([0.0, 0.0, -setup.load_n])
        peak = mean = setup.load_n / area
        disp = np.array([0.0, 0.0, -setup.approach_mm()])  # M's bone moves down, along the load
        xs, ys = np.linspace(0.0, setup.lx_mm, 21), np.linspace(0.0, setup.ly_mm, 17)
        z = 0.0  # M's contact face
        exact = {"approach_mm": setup.approach_mm(), "formula": "p = F / A, d = p (h_M / E'_M + h_F / E'_F)"}
        pressure_of = lambda x: np.full(np.shape(x), peak)  # noqa: E731
    else:
        area = CONFINED.lx_mm * CONFINED.ly_mm
        force = np.array([0.0, 0.0, CONFINED.load_n])
        peak = mean = CONFINED.load_n / area
        d = cf.confined_compression_displacement(e, nu, CONFINED.thickness_mm, peak)
        disp = d * force / np.linalg.norm(force)  # the bone moves along the load
        xs, ys = np.linspace(0.0, CONFINED.lx_mm, 21), np.linspace(0.0, CONFINED.ly_mm, 17)
        z = CONFINED.thickness_mm
        exact = {"confined_modulus_mpa": cf.confined_modulus(e, nu), "approach_mm": d, "formula": "p = F / A, d = p h / E' (p = E' d / h)"}
        pressure_of = lambda x: np.full(np.shape(x), peak)  # noqa: E731
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    points = np.column_stack([gx.ravel(), gy.ravel(), z(gx.ravel()) if callable(z) else np.full(gx.size, z)])
    nx, ny = len(xs), len(ys)
    idx = np.arange(nx * ny).reshape(nx, ny)
    quads = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], axis=-1).reshape(-1, 4)
    triangles = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    pressure = np.asarray(pressure_of(points[:, 0]), dtype=np.float64)
    cells = np.asarray(pressure_of(points[triangles].mean(axis=1)[:, 0]), dtype=np.float64)
    summary = {
        "scene": f"fe-problem:{name}",
        "method": f"closed-form:{name}",
        "n_springs": 0,
        "wall_time_s": time.perf_counter() - start,
        "closed_form": {"name": name, **exact},
    }
    return write_static_result_dir(
        out_dir, summary=summary, force_n=force, displacement_mm=disp, peak_pressure_mpa=peak, mean_pressure_mpa=mean,
        contact_area_mm2=area, points_mm=points, triangles=triangles, point_data={"pressure_mpa": pressure},
        cell_data={"pressure_mpa": cells, "in_contact": (cells > 0).astype(np.int8)},
    )


def half_width_errors(a_summary: dict[str, Any], b_summary: dict[str, Any]) -> dict[str, float]:
    """Relative errors of the FE half-width (contact area / slice; and the elliptic fit) against Hertz."""
    exact = b_summary.get("closed_form", {}).get("half_width_mm")
    fe = a_summary.get("fe_problem", {})
    out = {}
    if exact and "half_width_mm" in fe:
        out["half_width_rel_error"] = abs(fe["half_width_mm"] - exact) / exact
    if exact and "half_width_fit_mm" in fe:
        out["half_width_fit_rel_error"] = abs(fe["half_width_fit_mm"] - exact) / exact
    return out


def observed_orders(sizes: list[float], values: list[float], mode: str = "vs-exact") -> list[float]:
    """Observed convergence orders of a mesh sweep (coarsest first).

    "vs-exact": log(e_i / e_{i+1}) / log(h_i / h_{i+1}) between successive meshes, from errors
    against an exact value; "richardson": log(|f1 - f2| / |f2 - f3|) / log(r) from three
    solutions on meshes refined by a constant ratio r (no exact value needed).
    """
    h = np.asarray(sizes, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    if mode == "vs-exact":
        with np.errstate(divide="ignore", invalid="ignore"):
            return [float(x) for x in np.log(np.abs(v[:-1]) / np.abs(v[1:])) / np.log(h[:-1] / h[1:])]
    if mode == "richardson":
        if len(v) != 3:
            raise ValueError("Richardson's observed order needs three solutions")
        ratio = h[0] / h[1]
        if not math.isclose(ratio, h[1] / h[2], rel_tol=1e-6):
            raise ValueError("Richardson's observed order needs a constant refinement ratio")
        d12, d23 = abs(v[0] - v[1]), abs(v[1] - v[2])
        return [math.inf if d23 == 0.0 else math.log(d12 / d23) / math.log(ratio)]
    raise ValueError(f"unknown order mode {mode!r}")

