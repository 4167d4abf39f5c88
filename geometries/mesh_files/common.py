"""What the mesh file families share: the formats read, the coordinate bound, cell arrays and
the error of an unreadable file."""

from __future__ import annotations

import numpy as np

from geometries.errors import InputError

SUPPORTED_FORMATS = "STL (ascii or binary), OBJ, PLY, VTK (legacy), VTU or VTP"

#: largest coordinate magnitude a mesh may have, mm (1 km)
MAX_COORDINATE_MM = 1e6

#: cells as (size of every cell, their vertex indices concatenated)
Cells = tuple[np.ndarray, np.ndarray]


def unreadable(detail: str, file: str, key: str | None) -> InputError:
    return InputError(f"could not read the mesh ({detail})", file=file, key=key,
                      expected=f"a valid {SUPPORTED_FORMATS} file")


def cells_of(offsets: np.ndarray, connectivity: np.ndarray, ids: np.ndarray) -> Cells:
    """The cells ``ids`` of an offsets/connectivity cell array."""
    start = offsets[ids]
    size = offsets[ids + 1] - start
    first = np.cumsum(size) - size  # start of each cell in the output
    return size, connectivity[np.repeat(start - first, size) + np.arange(size.sum())]


def block(cells: np.ndarray) -> Cells:
    """An (n, k) array of cells of k vertices."""
    cells = np.asarray(cells, dtype=np.int64)
    return np.full(len(cells), cells.shape[1], dtype=np.int64), cells.ravel()


def fmt_point(p: np.ndarray) -> str:
    return "(" + ", ".join(f"{float(x):.4g}" for x in p) + ") mm"


#: what a family's reader gives: points (n, 3), polygons, triangle strips, cell type names
MeshCells = tuple[np.ndarray, list[Cells], list[Cells], list[str]]
