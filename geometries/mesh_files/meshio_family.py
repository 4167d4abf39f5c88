"""STL, OBJ and PLY: read and written through meshio's public API, the format named by the
extension (docs/method.md#8-built-in-geometries)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from geometries.mesh_files.common import MeshCells, block, unreadable
from geometries.surface import TriangleSurface


#: the formats of this family, by extension
FORMATS = {".stl": "stl", ".obj": "obj", ".ply": "ply"}

#: where a PLY file's header must have ended (its element and property lines, and comments)
_PLY_HEADER_BYTES = 1 << 20


def read(path: Path, key: str | None) -> MeshCells:
    """Points, polygons (triangles, quads, larger polygons), no strips, and the cell type names
    of an STL, OBJ or PLY file."""
    file_format = FORMATS[path.suffix.lower()]
    if file_format == "ply":
        # meshio's PLY reader loops for ever on a header cut before its end (it reads empty
        # lines at the end of the file); a header is a few hundred bytes of text.
        with path.open("rb") as stream:
            head = stream.read(_PLY_HEADER_BYTES)
        if b"end_header" not in head:
            raise unreadable(f"no 'end_header' line in its first {_PLY_HEADER_BYTES // 1024} KiB: a PLY header cut short", str(path), key)
    mesh = read_meshio(path, file_format, key)
    points = np.asarray(mesh.points, dtype=np.float64)
    if points.ndim == 2 and points.shape[1] == 2:
        points = np.column_stack([points, np.zeros(len(points))])
    polys = [block(cells.data) for cells in mesh.cells
             if cells.type in ("triangle", "quad", "polygon") and np.ndim(cells.data) == 2]
    return points, polys, [], [cells.type for cells in mesh.cells]


def read_meshio(path: Path, file_format: str, key: str | None):
    """``meshio.read`` of ``path`` as ``file_format``; its failures become InputError naming the
    file and ``key``."""
    import meshio

    file = str(path)
    try:
        with warnings.catch_warnings():
            # meshio's STL reader can overflow harmlessly while telling ascii from binary
            warnings.simplefilter("ignore", RuntimeWarning)
            mesh = meshio.read(path, file_format=file_format)
    except SystemExit:  # meshio.read prints a reader's ReadError and calls sys.exit(1)
        raise unreadable(f"not a readable {file_format.upper()} file", file, key) from None
    except Exception as exc:  # the readers also raise ValueError, IndexError, UnicodeError...
        raise unreadable(str(exc).strip() or type(exc).__name__, file, key) from None
    return mesh


def write(path: Path, surface: TriangleSurface, binary: bool | None) -> None:
    """Write the triangles through ``meshio.write``. ``binary=None`` picks the lossless variant:
    ascii STL (binary STL stores float32), binary PLY (float64); OBJ is always ascii (full
    float repr)."""
    write_meshio(path, surface, FORMATS[path.suffix.lower()], binary)


#: formats whose binary variant is lossless (float64 points), written binary by default
_BINARY_BY_DEFAULT = ("ply", "vtk", "vtu")


def write_meshio(path: Path, surface: TriangleSurface, file_format: str, binary: bool | None) -> None:
    """``meshio.write`` of the surface's triangles as ``file_format`` (``binary=None``: binary
    where that is lossless, ascii STL)."""
    import meshio

    kwargs = {}
    if file_format == "stl":
        kwargs["binary"] = False if binary is None else binary
    elif file_format in _BINARY_BY_DEFAULT:
        kwargs["binary"] = True if binary is None else binary
    mesh = meshio.Mesh(np.asarray(surface.vertices_mm, dtype=np.float64),
                       [("triangle", np.asarray(surface.triangles, dtype=np.int64))])
    meshio.write(path, mesh, file_format=file_format, **kwargs)
