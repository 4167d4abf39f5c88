"""gmsh sessions and the meshing helpers of the curved builders (gmsh is imported only here,
inside the functions that mesh; a plate or hemisphere scene never loads it).

Meshing is deterministic: one thread, Frontal-Delaunay (algorithm 6), fixed random seed and
random factor; the same parameters give identical arrays.
"""

from __future__ import annotations

import contextlib
import itertools
from collections.abc import Iterator
from typing import Any

import numpy as np

from geometries.extras import import_extra

_MODEL_COUNTER = itertools.count()


@contextlib.contextmanager
def gmsh_model(name: str) -> Iterator[Any]:
    """A fresh gmsh model with deterministic meshing options; yields the ``gmsh`` module.

    Works whether or not gmsh is already initialised by the caller: an existing session is left
    as it was (its current model and the options set here are restored); otherwise gmsh is
    initialised (quietly, without touching the SIGINT handler) and finalised on exit. Without
    gmsh (the ``gmsh`` extra) raises :class:`~geometries.extras.MissingExtra`.
    """
    gmsh = import_extra("gmsh", "meshing a curved geometry (the ideal and subject-like ankles, the FE solids)")

    owns = not gmsh.isInitialized()
    if owns:
        gmsh.initialize(readConfigFiles=False, interruptible=False)
    options = {
        "General.Terminal": 0,
        "General.Verbosity": 0,
        "General.NumThreads": 1,
        "Mesh.MaxNumThreads1D": 1,
        "Mesh.MaxNumThreads2D": 1,
        "Mesh.MaxNumThreads3D": 1,
        "Mesh.Algorithm": 6,
        "Mesh.RandomSeed": 1,
        "Mesh.RandomFactor": 1e-9,
        "Mesh.MeshSizeFromCurvature": 0,
        "Mesh.MeshSizeExtendFromBoundary": 1,
        "Mesh.MeshSizeFromPoints": 1,
        "Mesh.MeshSizeMin": 0,
        "Mesh.MeshSizeMax": 1e22,
        "Mesh.Optimize": 0,
        "Mesh.Smoothing": 1,
    }
    previous_model = None
    saved: dict[str, float] = {}
    try:
        if not owns:
            with contextlib.suppress(Exception):
                previous_model = gmsh.model.getCurrent()
            for k in options:
                with contextlib.suppress(Exception):
                    saved[k] = gmsh.option.getNumber(k)
        for k, v in options.items():
            with contextlib.suppress(Exception):  # an option missing in some gmsh version
                gmsh.option.setNumber(k, v)
        model_name = f"edem_{name}_{next(_MODEL_COUNTER)}"
        gmsh.model.add(model_name)
        yield gmsh
    finally:
        if owns:
            gmsh.finalize()
        else:
            with contextlib.suppress(Exception):
                gmsh.model.remove()
            for k, v in saved.items():
                with contextlib.suppress(Exception):
                    gmsh.option.setNumber(k, v)
            if previous_model:
                with contextlib.suppress(Exception):
                    gmsh.model.setCurrent(previous_model)


def gmsh_triangles(gmsh: Any, dim_tags: list[tuple[int, int]] | None = None,
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (n, 3) and 3-node triangles (m, 3) of the current gmsh model, compacted.

    With ``dim_tags`` only triangles of those surfaces are returned (in the given order).
    """
    node_tags, coords, _ = gmsh.model.mesh.getNodes()
    node_tags = np.asarray(node_tags, dtype=np.int64)
    coords = np.asarray(coords, dtype=np.float64).reshape(-1, 3)
    tris = []
    surfaces = dim_tags if dim_tags is not None else [(2, -1)]
    for _dim, tag in surfaces:
        _etags, enodes = gmsh.model.mesh.getElementsByType(2, tag)
        tris.append(np.asarray(enodes, dtype=np.int64).reshape(-1, 3))
    tri_tags = np.concatenate(tris, axis=0)
    lookup = np.full(int(node_tags.max()) + 1, -1, dtype=np.int64)
    lookup[node_tags] = np.arange(node_tags.size)
    tri_idx = lookup[tri_tags]
    used = np.unique(tri_idx)
    compact = np.full(node_tags.size, -1, dtype=np.int64)
    compact[used] = np.arange(used.size)
    return coords[used].copy(), compact[tri_idx]


def mesh_planar_domain(
    name: str,
    polygons: list[list[tuple[float, float]]],
    mesh_size: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mesh a set of planar polygons in the (a, b) plane with gmsh, conforming on shared edges.

    ``polygons`` are counter-clockwise vertex lists; polygons may share whole edges (same two
    vertices), which are then meshed once. Returns the 2D vertices (n, 2), triangles (m, 3)
    oriented counter-clockwise in (a, b), and the index of the polygon each triangle belongs to.
    """
    with gmsh_model(name) as gmsh:
        geo = gmsh.model.geo
        point_tag: dict[tuple[float, float], int] = {}
        line_tag: dict[tuple[int, int], int] = {}
        surfaces = []
        for poly in polygons:
            pts = []
            for a, b in poly:
                key = (round(a, 12), round(b, 12))
                if key not in point_tag:
                    point_tag[key] = geo.addPoint(a, b, 0.0, mesh_size)
                pts.append(point_tag[key])
            loop = []
            for i in range(len(pts)):
                p, q = pts[i], pts[(i + 1) % len(pts)]
                if (q, p) in line_tag:
                    loop.append(-line_tag[(q, p)])
                else:
                    if (p, q) not in line_tag:
                        line_tag[(p, q)] = geo.addLine(p, q)
                    loop.append(line_tag[(p, q)])
            surfaces.append(geo.addPlaneSurface([geo.addCurveLoop(loop)]))
        geo.synchronize()
        gmsh.model.mesh.generate(2)
        counts = []
        for s in surfaces:
            _e, en = gmsh.model.mesh.getElementsByType(2, s)
            counts.append(len(en) // 3)
        verts, tris = gmsh_triangles(gmsh, [(2, s) for s in surfaces])
    verts2 = verts[:, :2]
    # orient counter-clockwise in the (a, b) plane
    a, b, c = verts2[tris[:, 0]], verts2[tris[:, 1]], verts2[tris[:, 2]]
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    tris = tris.copy()
    flip = cross < 0
    tris[flip] = tris[flip][:, [0, 2, 1]]
    region = np.repeat(np.arange(len(surfaces)), counts)
    return verts2, tris, region


def orient_like(vertices: np.ndarray, triangles: np.ndarray, expected_normals: np.ndarray,
                 what: str) -> np.ndarray:
    """Flip the whole (consistently oriented) mesh if its normals oppose ``expected_normals``.

    gmsh orients every triangle of one surface alike; we flip globally (never per triangle) and
    then assert every triangle agrees with the analytic normal, so orientation comes from the
    mesh topology and the check only confirms it.
    """
    a, b, c = vertices[triangles[:, 0]], vertices[triangles[:, 1]], vertices[triangles[:, 2]]
    n = np.cross(b - a, c - a)
    s = np.einsum("ij,ij->i", n, expected_normals)
    if np.sum(s) < 0:
        triangles = triangles[:, [0, 2, 1]]
        s = -s
    if not np.all(s > 0):
        raise RuntimeError(f"{what}: inconsistent triangle orientation from the mesher")
    return np.ascontiguousarray(triangles, dtype=np.int64)
