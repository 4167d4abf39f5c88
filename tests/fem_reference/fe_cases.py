"""Shared cases and helpers for the FE contact verification tests (small meshes, 2 shared cores)."""

from __future__ import annotations

import math

import numpy as np
from fem_reference import (
    FEContactProblem,
    NitscheParameters,
    RigidCylinder,
    RigidPlane,
    RigidSurface,
    Roller,
)
from fem_reference import closed_forms as cf

MATERIAL = {"youngs_modulus_mpa": 10.35, "poissons_ratio": 0.42}  # docs/references.md#the-thesiss-figures cartilage

# Hertz set-up: rigid cylinder R = 20 mm on a block 20 a wide (half model) and 20 a thick,
# bonded to a rigid base; load chosen for a half-width a = 1 mm (a / R = 0.05: small strain).
HERTZ_R = 20.0
HERTZ_A = 1.0
HERTZ_BLOCK = 20.0


def world():
    """MPI.COMM_WORLD, imported in the order the dolfinx wheel requires."""
    import dolfinx_solver  # noqa: F401
    from mpi4py import MPI

    return MPI.COMM_WORLD


def hertz_reference() -> cf.HertzLine:
    return cf.HertzLine.for_half_width(HERTZ_A, HERTZ_R, **MATERIAL)


def hertz_mesh(comm, size_contact: float, *, size_far: float | None = None):
    from fem_reference import meshes

    return meshes.hertz_block(comm, width=HERTZ_BLOCK, height=HERTZ_BLOCK,
                              slice_thickness=size_contact, size_contact=size_contact,
                              size_far=size_far if size_far is not None else 10 * size_contact,
                              fine_radius=1.5 * HERTZ_A, coarse_radius=15.0)


def hertz_problem(fe_mesh, slice_thickness: float, *, element: str = "P2", obstacle=None,
                  **kw) -> FEContactProblem:
    """Half model (symmetry x = 0), plane strain slice: load = P' * slice / 2 on the base."""
    ref = hertz_reference()
    if obstacle is None:
        obstacle = RigidCylinder((0.0, 0.0, HERTZ_BLOCK + HERTZ_R), (0.0, 1.0, 0.0), HERTZ_R)
    return FEContactProblem(
        mesh=fe_mesh, obstacle=obstacle, element=element,
        force_n=(0.0, 0.0, ref.load_per_length_n_per_mm * slice_thickness / 2.0),
        rollers=(Roller(4, "x"), Roller(5, "y")), **MATERIAL, **kw)


def triangulated_cylinder(radius: float, axis_point, y_range, half_angle_deg: float,
                          n_theta: int, n_y: int = 2) -> RigidSurface:
    """Cylinder patch (axis along y) around its lowest line, normals pointing away from the
    axis (towards a body below it)."""
    th = np.linspace(-math.radians(half_angle_deg), math.radians(half_angle_deg), n_theta + 1)
    ys = np.linspace(y_range[0], y_range[1], n_y + 1)
    cx, _, cz = axis_point
    T, Y = np.meshgrid(th, ys, indexing="ij")
    verts = np.column_stack([cx + radius * np.sin(T).ravel(), Y.ravel(),
                             cz - radius * np.cos(T).ravel()])
    idx = np.arange(verts.shape[0]).reshape(T.shape)
    tris = []
    for i in range(n_theta):
        for j in range(n_y):
            a, b, c, d = idx[i, j], idx[i + 1, j], idx[i + 1, j + 1], idx[i, j + 1]
            tris += [(a, b, c), (a, c, d)]
    surf = RigidSurface(verts, np.array(tris))
    # orient: a point below the cylinder must have a positive gap
    g, _ = surf.gap_and_normal(np.array([[cx, 0.5 * sum(y_range), cz - 2 * radius]]))
    return surf if g[0] > 0 else RigidSurface(verts, np.array(tris), flip_normals=True)


def plane_as_surface(point, normal, half_size: float = 1e3) -> RigidSurface:
    """Two triangles spanning a large square of the plane, oriented along ``normal``."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    t1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n, t1)
    p = np.asarray(point, float)
    v = np.array([p + half_size * (s1 * t1 + s2 * t2) for s1, s2 in
                  [(-1, -1), (1, -1), (1, 1), (-1, 1)]])
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    surf = RigidSurface(v, tris)
    return surf if surf.gap_and_normal(p[None, :] + n)[0][0] > 0 else RigidSurface(
        v, tris, flip_normals=True)


def report(title: str, **values) -> None:
    """Print the numbers a test checked (visible with pytest -s)."""
    def fmt(v):
        if isinstance(v, (float, np.floating)):
            return f"{float(v):.6g}"
        if isinstance(v, (list, tuple, np.ndarray)):
            return "[" + ", ".join(fmt(x) for x in v) + "]"
        return str(v)

    parts = [f"{k}={fmt(v)}" for k, v in values.items()]
    print(f"\n[fe] {title}: " + ", ".join(parts))


__all__ = ["MATERIAL", "NitscheParameters", "RigidPlane", "hertz_problem", "hertz_mesh", "world",
           "hertz_reference", "triangulated_cylinder", "plane_as_surface", "report"]
