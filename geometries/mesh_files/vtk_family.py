"""Legacy VTK (.vtk), VTK XML PolyData (.vtp) and UnstructuredGrid (.vtu), both ways
(docs/method.md#8-built-in-geometries): read by VTK's own readers in a forked child process (a
crash there is an InputError naming the file), written in Python (.vtp, :func:`write_vtp`) or
through meshio (.vtk, .vtu). VTK's polygon triangulation (vtkTriangleFilter), used for every
family's quads and polygons, lives here too; VTK itself is the ``vtk`` extra."""

from __future__ import annotations

import base64
import html
import importlib
import os
import re
import signal
import sys
import threading
import warnings
from pathlib import Path

import numpy as np

from geometries.errors import MeshWarning
from geometries.extras import MissingExtra, extra_of
from geometries.mesh_files.child import run_in_child
from geometries.mesh_files.common import SUPPORTED_FORMATS, Cells, MeshCells, block, cells_of, unreadable
from geometries.mesh_files.meshio_family import write_meshio
from geometries.surface import TriangleSurface


#: the formats of this family, by extension
FORMATS = (".vtk", ".vtp", ".vtu")

#: VTK cell types of the 2D cells kept as polygons, with their corner nodes in polygon order:
#: triangle, quad, pixel (reordered into a quad), then higher-order triangles (quadratic,
#: biquadratic, Lagrange, Bezier) and quads (quadratic, biquadratic, quadratic-linear,
#: Lagrange, Bezier) through their corner nodes only. Strips (6) and polygons (7) are kept
#: whole; vtkTriangleFilter triangulates them all.
_CORNERS = {5: (0, 1, 2), 9: (0, 1, 2, 3), 8: (0, 1, 3, 2)}
_CORNERS.update(dict.fromkeys((22, 34, 69, 76), (0, 1, 2)))
_CORNERS.update(dict.fromkeys((23, 28, 30, 70, 77), (0, 1, 2, 3)))
_LINEAR_2D = (5, 6, 7, 8, 9)


#: The VTK modules this project reads through (mesh import, triangulation, result pressure maps).
VTK_MODULES = (
    "vtkmodules.util.numpy_support", "vtkmodules.util.vtkConstants", "vtkmodules.util.misc",
    "vtkmodules.vtkCommonCore", "vtkmodules.vtkCommonDataModel", "vtkmodules.vtkFiltersCore",
    "vtkmodules.vtkIOLegacy", "vtkmodules.vtkIOXML",
)


def load_vtk(purpose: str = "reading VTK files") -> None:
    """Import :data:`VTK_MODULES` with Ctrl-C held back until they are loaded.

    A KeyboardInterrupt inside the import of a VTK extension module leaves it half initialised:
    VTK's loader reports an ImportError, or the process crashes (SIGSEGV) in VTK's module
    registry. Blocking the signal is not enough (Python's handler runs for a signal any thread
    receives), so the Python-level handler is swapped for one that only records the interrupt,
    which is then handed to the previous handler once the modules are in.

    Without VTK (the ``vtk`` extra) raises :class:`~geometries.extras.MissingExtra`, saying
    that ``purpose`` needs it.
    """
    if all(name in sys.modules for name in VTK_MODULES):
        return
    if threading.current_thread() is not threading.main_thread():  # handlers belong to the main thread
        _import_vtk(purpose)
        return
    pending: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: pending.append(signum))
    try:
        _import_vtk(purpose)
    finally:
        signal.signal(signal.SIGINT, previous)
    if pending and callable(previous):
        previous(signal.SIGINT, None)
    elif pending and previous == signal.SIG_DFL:
        os.kill(os.getpid(), signal.SIGINT)


def _import_vtk(purpose: str) -> None:
    try:
        for name in VTK_MODULES:
            importlib.import_module(name)
    except ModuleNotFoundError as exc:
        if extra_of(exc) != "vtk":
            raise
        raise MissingExtra("vtk", "vtk", purpose) from None


def _vtk_polydata(points: np.ndarray, polys: Cells, strips: Cells | None = None):
    """A vtkPolyData of float64 points, polygons and triangle strips (int64 vertex indices)."""
    load_vtk()
    from vtkmodules.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData

    poly = vtkPolyData()
    vtk_points = vtkPoints()
    vtk_points.SetData(numpy_to_vtk(np.ascontiguousarray(points, dtype=np.float64), deep=True))
    poly.SetPoints(vtk_points)
    for cells, setter in ((polys, poly.SetPolys), (strips, poly.SetStrips)):
        if cells is None:
            continue
        sizes, connectivity = cells
        offsets = np.concatenate([[0], np.cumsum(sizes, dtype=np.int64)])
        array = vtkCellArray()
        array.SetData(numpy_to_vtkIdTypeArray(offsets, deep=True),
                      numpy_to_vtkIdTypeArray(np.ascontiguousarray(connectivity, dtype=np.int64),
                                              deep=True))
        setter(array)
    return poly


def triangulate(points: np.ndarray, polys: list[Cells], strips: list[Cells]) -> np.ndarray:
    """Triangles of polygons and triangle strips, by VTK's vtkTriangleFilter.

    Triangles pass unchanged; larger polygons are triangulated keeping their winding (quads
    along the shorter diagonal); strips are unrolled with VTK's alternating-winding rule.
    """
    load_vtk("a mesh of quads, polygons or triangle strips (VTK triangulates them)")
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkFiltersCore import vtkTriangleFilter

    def joined(cells: list[Cells]) -> Cells | None:
        if not cells:
            return None
        return np.concatenate([s for s, _ in cells]), np.concatenate([c for _, c in cells])

    if not any(len(sizes) for sizes, _ in polys + strips):
        return np.empty((0, 3), dtype=np.int64)
    triangle_filter = vtkTriangleFilter()
    triangle_filter.PassVertsOff()
    triangle_filter.PassLinesOff()
    triangle_filter.SetInputData(_vtk_polydata(points, joined(polys), joined(strips)))
    triangle_filter.Update()
    cells = triangle_filter.GetOutput().GetPolys()
    connectivity = vtk_to_numpy(cells.GetConnectivityArray()).astype(np.int64)
    offsets = vtk_to_numpy(cells.GetOffsetsArray()).astype(np.int64)
    # Degenerate input polygons can come out as cells of fewer than 3 points: keep triangles only.
    starts = offsets[:-1][np.diff(offsets) == 3]
    return connectivity[starts[:, None] + np.arange(3)]


#: the most points, cells or components a VTK XML file may declare (a joint surface has < 1e7)
_MAX_XML_COUNT = 10**9


def _check_header(path: Path, key: str | None) -> None:
    """Refuse what VTK's readers were seen to crash on, with a message that says what is wrong
    (the child process would only tell that the reader crashed)."""
    if path.suffix.lower() in (".vtp", ".vtu"):
        _check_xml_counts(path, key)
    else:
        # VTK reads a version line it cannot parse as an older layout (a warning only) and then
        # crashes on a 5.1 file's cell arrays (found by a mesh fuzz).
        with path.open("rb") as stream:
            first = stream.readline(256)
        if not re.fullmatch(rb"# vtk DataFile Version \d+\.\d+\s*", first):
            raise unreadable(f"its first line is {first[:60]!r}, not '# vtk DataFile Version <major>.<minor>'", str(path), key)


def _check_xml_counts(path: Path, key: str | None) -> None:
    """Refuse a VTK XML file whose declared sizes (``NumberOfPoints``, ``NumberOfCells``,
    ``NumberOfComponents``...) are not whole numbers in range: VTK's XML readers resize their
    arrays to them unchecked, and a negative or huge one aborts the process (a mesh fuzz found
    ``NumberOfComponents="-3"``). Read as bytes up to the appended binary data, if any."""
    with path.open("rb") as stream:
        text = stream.read()
    text = text.split(b"<AppendedData", 1)[0]
    for name, value in re.findall(rb'(NumberOf\w+)\s*=\s*"([^"]*)"', text):
        low = 1 if name == b"NumberOfComponents" else 0
        if not (re.fullmatch(rb"\s*\d{1,10}\s*", value) and low <= int(value) <= _MAX_XML_COUNT):
            raise unreadable(f"{name.decode()}=\"{value.decode(errors='replace')[:20]}\" is not a whole number "
                              f"from {low} to {_MAX_XML_COUNT:.0e}", str(path), key)


def _read_vtk(path: Path, key: str | None):
    """The dataset of a VTK file, read by VTK's own readers: legacy .vtk of any dataset type,
    XML .vtp (PolyData) and .vtu (UnstructuredGrid).

    VTK readers do not raise: they report failures as error events, collected here from the
    reader and its executive and raised as InputError.
    """
    load_vtk()
    from vtkmodules.util import vtkConstants as vtk_type
    from vtkmodules.util.misc import calldata_type
    from vtkmodules.vtkIOLegacy import (
        vtkGenericDataObjectReader,
        vtkPolyDataReader,
        vtkRectilinearGridReader,
        vtkStructuredGridReader,
        vtkStructuredPointsReader,
        vtkUnstructuredGridReader,
    )
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader, vtkXMLUnstructuredGridReader

    file = str(path)
    errors: list[str] = []

    @calldata_type(vtk_type.VTK_STRING)
    def on_error(_obj, _event, text: str) -> None:
        # text: "ERROR: In <source>, line <n>\n<class> (<address>): <message>"
        errors.append(" ".join(str(text).split("): ", 1)[-1].split()))

    def watched(obj):
        obj.AddObserver("ErrorEvent", on_error)
        return obj

    if path.suffix.lower() == ".vtk":
        # the generic legacy reader names the dataset type; that type's own reader reads it
        # (the generic one would swallow its delegate's errors)
        sniffer = watched(vtkGenericDataObjectReader())
        sniffer.SetFileName(file)
        reader_class = {
            vtk_type.VTK_POLY_DATA: vtkPolyDataReader,
            vtk_type.VTK_UNSTRUCTURED_GRID: vtkUnstructuredGridReader,
            vtk_type.VTK_STRUCTURED_GRID: vtkStructuredGridReader,
            vtk_type.VTK_RECTILINEAR_GRID: vtkRectilinearGridReader,
            vtk_type.VTK_STRUCTURED_POINTS: vtkStructuredPointsReader,
            vtk_type.VTK_IMAGE_DATA: vtkStructuredPointsReader,
        }.get(sniffer.ReadOutputType())
    elif path.suffix.lower() == ".vtp":
        reader_class = vtkXMLPolyDataReader
    else:
        reader_class = vtkXMLUnstructuredGridReader
    if reader_class is not None and not errors:
        reader = reader_class()
        tag = reader.AddObserver("ErrorEvent", on_error)
        watched(reader.GetExecutive())
        if path.suffix.lower() != ".vtk":  # the XML reader's parser reports to it as well
            reader.SetParserErrorObserver(reader.GetCommand(tag))
        reader.SetFileName(file)
        reader.Update()
    if errors:
        raise unreadable(errors[0], file, key)
    if reader_class is None:
        raise unreadable("not a legacy VTK dataset file", file, key)
    return reader.GetOutput()


def _vtk_cells(data, file: str, key: str | None) -> MeshCells:
    """Points, polygons, triangle strips and cell type names of a VTK dataset.

    PolyData: its polygons and strips (vertices and lines ignored). Other datasets: their 2D
    cells (a volume mesh's 3D cells are ignored, not turned into a boundary surface); higher-
    order triangles and quads keep their corner nodes (warning); other 2D cells are dropped
    (warning).
    """
    load_vtk()
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkCommonDataModel import vtkCellTypeUtilities
    from vtkmodules.vtkFiltersCore import vtkAppendFilter

    def name(cell_type: int) -> str:
        return vtkCellTypeUtilities.GetClassNameFromTypeId(int(cell_type))[3:].lower()

    def arrays(cells) -> tuple[np.ndarray, np.ndarray]:
        offsets = vtk_to_numpy(cells.GetOffsetsArray()).astype(np.int64)
        connectivity = vtk_to_numpy(cells.GetConnectivityArray()).astype(np.int64)
        # VTK's legacy readers take a corrupted binary cell array as it comes (a fuzz found
        # offsets of 1e18, on which VTK's own cell walks crash the process): checked before any
        # of them, the offsets must walk the connectivity once, from its start to its end.
        if offsets.size and (offsets[0] != 0 or offsets[-1] != connectivity.size or np.any(np.diff(offsets) < 0)):
            raise unreadable("its cell offsets do not walk its connectivity array once: a corrupted cell array", file, key)
        return offsets, connectivity

    if not data.IsA("vtkPolyData") and not data.IsA("vtkUnstructuredGrid"):
        to_grid = vtkAppendFilter()  # structured grids and images (implicit cells): as an unstructured grid
        to_grid.SetInputData(data)
        to_grid.Update()
        data = to_grid.GetOutput()
    # From here on, no VTK call walks the cells: their types and arrays are read as numbers.
    if data.IsA("vtkPolyData"):
        cell_arrays = [arrays(data.GetPolys()), arrays(data.GetStrips())]
        counts = zip(("vertex", "line", "polygon", "triangle_strip"), (data.GetNumberOfVerts(), data.GetNumberOfLines(), *(o.size - 1 for o, _ in cell_arrays)))
        types = [kind for kind, count in counts if count > 0]
    else:
        cell_types = vtk_to_numpy(data.GetCellTypes()) if data.GetNumberOfCells() else np.zeros(0, np.uint8)
        offsets, connectivity = arrays(data.GetCells()) if cell_types.size else (np.zeros(1, np.int64), np.zeros(0, np.int64))
        if offsets.size != cell_types.size + 1:
            raise unreadable(f"{cell_types.size} cell types for {offsets.size - 1} cells: a corrupted cell array", file, key)
        unknown = [int(t) for t in np.unique(cell_types) if vtkCellTypeUtilities.GetClassNameFromTypeId(int(t)) == "UnknownClass"]
        if unknown:
            raise unreadable(f"cell type {unknown[0]} is not a VTK cell type: a corrupted cell array", file, key)
        types = [name(t) for t in np.unique(cell_types)]
    if data.GetNumberOfPoints() == 0:
        points = np.empty((0, 3))
    else:
        points = vtk_to_numpy(data.GetPoints().GetData()).astype(np.float64)
    if data.IsA("vtkPolyData"):
        (poly_offsets, poly_connectivity), (strip_offsets, strip_connectivity) = cell_arrays
        return points, [(np.diff(poly_offsets), poly_connectivity)], [(np.diff(strip_offsets), strip_connectivity)], types

    polys, strips, dropped, corner_only = [], [], set(), set()
    for cell_type in np.unique(cell_types):
        ids = np.flatnonzero(cell_types == cell_type)
        if cell_type in (6, 7):  # triangle strip, polygon
            cells = cells_of(offsets, connectivity, ids)
            (strips if cell_type == 6 else polys).append(cells)
        elif cell_type in _CORNERS:
            need = max(_CORNERS[cell_type]) + 1
            if np.any(offsets[ids + 1] - offsets[ids] < need):
                raise unreadable(f"{name(cell_type)} cells with fewer than {need} points: a corrupted cell array", file, key)
            corners = offsets[ids][:, None] + np.asarray(_CORNERS[cell_type])
            polys.append(block(connectivity[corners]))
            if cell_type not in _LINEAR_2D:
                corner_only.add(name(cell_type))
        elif vtkCellTypeUtilities.GetDimension(int(cell_type)) == 2:
            dropped.add(name(cell_type))
    if corner_only:
        warnings.warn(f"{file}: higher-order cells ({', '.join(sorted(corner_only))}) were read as "
                      "flat triangles through their corner nodes; mid-side nodes ignored", MeshWarning, stacklevel=2)
    if dropped:
        warnings.warn(f"{file}: non-triangle 2D cells dropped ({', '.join(sorted(dropped))})", MeshWarning, stacklevel=2)
    return points, polys, strips, types


def read(path: Path, key: str | None) -> MeshCells:
    """Points, polygons, triangle strips and cell type names of a .vtk, .vtp or .vtu file, read
    so that no damage in the file can crash this process.

    VTK's own readers read the file in a forked child process (:func:`.child.run_in_child`):
    they trust their input, and a crash there ends the child, which is an InputError naming the
    file. meshio's Python readers (legacy VTK, VTU) cannot crash the process but do not check
    cell arrays against cell types: they read a damaged "triangle" of two points as (1, 0, 1),
    wrapping a negative index, and skip unknown cell types with a console message, so they are
    not used for these formats.
    """
    _check_header(path, key)
    load_vtk()  # imported once in this process; every child inherits the modules
    return run_in_child(_read_with_vtk, path, key, file=str(path), key=key,
                        expected=f"a valid {SUPPORTED_FORMATS} file")


def _read_with_vtk(path: Path, key: str | None) -> MeshCells:
    """:func:`read` by VTK's own readers (run in a child process)."""
    return _vtk_cells(_read_vtk(path, key), str(path), key)


#: VTK XML type names of the numpy types written (bool as UInt8: VTK's Bit is not byte-sized)
_VTK_XML_TYPES = {
    "float32": "Float32", "float64": "Float64", "int8": "Int8", "uint8": "UInt8", "int16": "Int16",
    "uint16": "UInt16", "int32": "Int32", "uint32": "UInt32", "int64": "Int64", "uint64": "UInt64",
}


#: bytes per zlib block, as VTK's own writer cuts them
_BLOCK_BYTES = 1 << 15
try:
    # ISA-L's deflate (the isal package, a dependency): the same zlib streams, on a run's pressure
    # maps (float64 points and pressures, int8 flags) 4.4x faster than zlib's fastest level and
    # 1-2 % smaller (a 13k-triangle map: 0.91 against 3.9 ms of CPU; 2026-11-28). Its level 2 is
    # as fast as its level 1 there, and level 0 only 20 % faster for files 17 % larger.
    from isal.isal_zlib import compress as _compress
    _ZLIB_LEVEL = 2
except ImportError:  # (an install without it writes the same arrays, through zlib)
    # zlib's fastest level: 2.6x faster than its default level 6 there, to arrays 5 % larger
    from zlib import compress as _compress
    _ZLIB_LEVEL = 1


def _xml_data_array(values: np.ndarray, name: str | None = None) -> str:
    """One ``<DataArray>`` in VTK XML's inline binary format, zlib-compressed as VTK writes it:
    the base64 of a UInt64 header (number of blocks, block size, size of the last block, the
    compressed size of each block), then the base64 of the compressed blocks of the
    little-endian values, row by row."""
    values = np.asarray(values)
    if values.dtype == np.bool_:
        values = values.astype(np.uint8)
    if values.dtype.name not in _VTK_XML_TYPES or values.ndim not in (1, 2):
        raise ValueError(f"write_vtp: array {name!r} of {values.dtype} and shape {values.shape} "
                         "(expected (n,) or (n, k) numbers)")
    data = np.ascontiguousarray(values, dtype=values.dtype.newbyteorder("<")).tobytes()
    blocks = [_compress(data[start:start + _BLOCK_BYTES], _ZLIB_LEVEL) for start in range(0, len(data), _BLOCK_BYTES)]
    last = len(data) - (len(blocks) - 1) * _BLOCK_BYTES if blocks else 0
    header = np.array([len(blocks), _BLOCK_BYTES, last, *map(len, blocks)], dtype="<u8").tobytes()
    encoded = (base64.b64encode(header) + base64.b64encode(b"".join(blocks))).decode("ascii")
    attributes = f'type="{_VTK_XML_TYPES[values.dtype.name]}"'
    if name is not None:
        attributes += f' Name="{html.escape(name, quote=True)}"'
    components = 1 if values.ndim == 1 else values.shape[1]
    return f'<DataArray {attributes} NumberOfComponents="{components}" format="binary">{encoded}</DataArray>'


def _vtp_polys(triangles: np.ndarray) -> str:
    """The ``<Polys>`` element of a .vtp of these triangles (int64 connectivity and offsets, compressed)."""
    connectivity = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    offsets = 3 * np.arange(1, len(connectivity) + 1, dtype=np.int64)
    return "<Polys>" + _xml_data_array(connectivity.ravel(), "connectivity") + _xml_data_array(offsets, "offsets") + "</Polys>"


class VtpSeries:
    """What the .vtp files of one series (a run's time points) share, encoded once and given to
    :func:`write_vtp` for each file: the triangles (one mesh at every time point) and every array
    equal to the one of that name in the file before (a run's measured thickness, an FE face's
    points on M): only the arrays that changed are compressed again."""

    def __init__(self) -> None:
        self._triangles: np.ndarray | None = None
        self._polys = ""
        self._arrays: dict[tuple[str, str], tuple[np.ndarray, str]] = {}

    def polys(self, triangles: np.ndarray) -> str:
        """The ``<Polys>`` element of ``triangles``."""
        if self._triangles is None or not (triangles is self._triangles or np.array_equal(triangles, self._triangles)):
            self._triangles, self._polys = triangles, _vtp_polys(triangles)
        return self._polys

    def array(self, section: str, name: str, values: np.ndarray) -> str:
        """The ``<DataArray>`` of ``values`` (a copy of each kept: a caller may reuse a buffer)."""
        values = np.asarray(values)
        known = self._arrays.get((section, name))
        if known is not None and known[0].dtype == values.dtype and known[0].shape == values.shape and np.array_equal(known[0], values):
            return known[1]
        text = _xml_data_array(values, name)
        self._arrays[(section, name)] = (values.copy(), text)
        return text


def write_vtp(
    path: str | Path, points_mm: np.ndarray, triangles: np.ndarray,
    cell_data: dict[str, np.ndarray] | None = None,
    point_data: dict[str, np.ndarray] | None = None,
    *,
    series: VtpSeries | None = None,
) -> None:
    """Write a triangulated surface, with optional per-triangle and per-vertex arrays, as VTK
    XML PolyData (docs/result-format.md).

    Parameters
    ----------
    path : str or Path
        The .vtp file.
    points_mm : (n_points, 3) array
        Vertex coordinates, mm; written as float64, so a round trip is exact.
    triangles : (n_triangles, 3) int array
        Vertex indices; written as int64 connectivity with int64 offsets.
    cell_data, point_data : dict of (n_triangles,) / (n_points,) or (n, k) arrays, optional
        Named arrays, written in their own numeric type (bool as UInt8).
    series : VtpSeries, optional
        The series this file belongs to, for the files of many time points: what they share is
        encoded once (the same bytes as encoded here).

    Every result directory's pressure maps are written here (the discrete runs write cell data,
    the FE runs nodal and facet data). The file is VTK XML's inline binary format (base64,
    zlib-compressed, UInt64 headers), which VTK, ParaView and pyvista read; it is written in
    Python, not by VTK, so that a run needs no VTK (the ``vtk`` extra) to write its results.
    A full disk is an OSError (ENOSPC): VTK's own file output crashed (SIGSEGV) there.
    """
    with open(path, "w", encoding="ascii") as f:
        f.write(vtp_text(points_mm, triangles, cell_data, point_data, series=series))


def vtp_text(
    points_mm: np.ndarray, triangles: np.ndarray,
    cell_data: dict[str, np.ndarray] | None = None,
    point_data: dict[str, np.ndarray] | None = None,
    *,
    series: VtpSeries | None = None,
) -> str:
    """The content of the .vtp file :func:`write_vtp` writes (ASCII text; arguments as there),
    for a writer that writes the file itself (a result directory's writer hashes it as written)."""
    points = np.asarray(points_mm, dtype=np.float64).reshape(-1, 3)
    n_triangles = np.asarray(triangles).reshape(-1, 3).shape[0]

    def data_section(tag: str, arrays: dict[str, np.ndarray] | None) -> str:
        encoded = (_xml_data_array(values, name) if series is None else series.array(tag, name, values) for name, values in (arrays or {}).items())
        return f"<{tag}>" + "".join(encoded) + f"</{tag}>"

    return ('<?xml version="1.0"?>\n'
            '<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" header_type="UInt64" '
            'compressor="vtkZLibDataCompressor">\n<PolyData>\n'
            f'<Piece NumberOfPoints="{len(points)}" NumberOfVerts="0" NumberOfLines="0" NumberOfStrips="0" '
            f'NumberOfPolys="{n_triangles}">\n'
            + data_section("PointData", point_data) + "\n" + data_section("CellData", cell_data) + "\n"
            + "<Points>" + _xml_data_array(points, "Points") + "</Points>\n"
            + (_vtp_polys(triangles) if series is None else series.polys(triangles))
            + "\n</Piece>\n</PolyData>\n</VTKFile>\n")


def write(path: Path, surface: TriangleSurface, binary: bool | None) -> None:
    """Write the triangles: .vtp through :func:`write_vtp` (binary float64), .vtk and .vtu
    through meshio (``binary=None``: binary, float64)."""
    if path.suffix.lower() == ".vtp":
        write_vtp(path, surface.vertices_mm, surface.triangles)
    else:
        write_meshio(path, surface, path.suffix.lower()[1:], binary)
