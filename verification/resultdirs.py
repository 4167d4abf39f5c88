"""Reading and writing SPEC 9 result directories (summary.json, timeseries.csv, pressure.pvd).

The same layout comes out of `edem run` (the mobile surface with cell data), `edem fe` (the FE
contact surface with point data ``pressure_mpa`` and cell data of the same names) and the closed
forms of :mod:`verification.closed_forms`. VTK is imported only by the functions that read or
write .vtp files.
"""

from __future__ import annotations

import csv
import json
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from edem.errors import InputError


@dataclass(frozen=True)
class SurfaceFrame:
    """One pressure_NNNN.vtp: a triangulated surface (mm) with its point and cell arrays."""

    points_mm: np.ndarray  # (n_points, 3)
    triangles: np.ndarray  # (n_triangles, 3) int64
    point_data: dict[str, np.ndarray] = field(default_factory=dict)
    cell_data: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def centroids_mm(self) -> np.ndarray:
        return self.points_mm[self.triangles].mean(axis=1)

    @property
    def areas_mm2(self) -> np.ndarray:
        a, b, c = (self.points_mm[self.triangles[:, i]] for i in range(3))
        return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


@dataclass(frozen=True)
class ResultDir:
    """A SPEC 9 result directory: summary, time series columns and one surface file per time."""

    path: Path
    summary: dict[str, Any]
    timeseries: dict[str, np.ndarray]  # column -> (n_times,) float
    frames: tuple[tuple[float, Path], ...]  # (time_s, .vtp path) from pressure.pvd

    @property
    def time_s(self) -> np.ndarray:
        return self.timeseries["time_s"]

    def frame(self, index: int) -> SurfaceFrame:
        return read_surface_frame(self.frames[index][1])


def read_result_dir(path: str | Path) -> ResultDir:
    """Read summary.json, timeseries.csv and the pressure.pvd index of a result directory (SPEC 9).

    Raises InputError naming the file when something of the layout is missing or unreadable,
    and when the directory does not verify against its manifest (a file missing, changed or
    left by another run: :func:`edem.atomic_dirs.verify_manifest`).
    """
    from edem.atomic_dirs import verify_manifest

    root = Path(path)
    expected = "a result directory of edem run / edem fe (summary.json, timeseries.csv, pressure.pvd)"
    if not root.is_dir():
        raise InputError("not a directory", file=root, expected=expected)
    if not (root / "summary.json").is_file():
        raise InputError("no summary.json here", file=root, expected=expected)
    verify_manifest(root)
    try:
        summary = json.loads((root / "summary.json").read_text(encoding="utf-8"))
    except ValueError as exc:
        raise InputError(f"summary.json is not valid JSON: {exc}", file=root / "summary.json") from None
    series = read_timeseries_csv(root / "timeseries.csv")
    pvd = root / "pressure.pvd"
    try:
        tree = ET.parse(pvd)
    except FileNotFoundError:
        raise InputError("no pressure.pvd here", file=root, expected=expected) from None
    except ET.ParseError as exc:
        raise InputError(f"pressure.pvd is not valid XML: {exc}", file=pvd) from None
    frames = tuple(
        (float(node.get("timestep", "0")), root / str(node.get("file")))
        for node in tree.getroot().iter("DataSet")
    )
    if not frames:
        raise InputError("pressure.pvd lists no data set", file=pvd, expected="one <DataSet> per time point")
    return ResultDir(root, summary, series, frames)


def read_timeseries_csv(path: str | Path) -> dict[str, np.ndarray]:
    """Columns of a timeseries.csv (SPEC 9) as float arrays."""
    path = Path(path)
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = list(csv.reader(f))
    except FileNotFoundError:
        raise InputError("no timeseries.csv here", file=path.parent, expected="a SPEC 9 result directory") from None
    if not rows:
        raise InputError("empty timeseries.csv", file=path, expected="a header and one row per time point")
    header = rows[0]
    try:
        data = np.array(rows[1:], dtype=float).reshape(-1, len(header))
    except ValueError:
        raise InputError("timeseries.csv has non-numeric or ragged rows", file=path, expected="numbers, one per column") from None
    if "time_s" not in header:
        raise InputError("timeseries.csv has no time_s column", file=path, expected="the SPEC 9 columns")
    return {name: data[:, i] for i, name in enumerate(header)}


def read_surface_frame(path: str | Path) -> SurfaceFrame:
    """Points, triangles and the point/cell arrays of a .vtp (polygons fan-triangulated by VTK)."""
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkFiltersCore import vtkTriangleFilter
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

    path = Path(path)
    if not path.is_file():
        raise InputError("surface file listed in pressure.pvd is missing", file=path, expected="a .vtp file")
    reader = vtkXMLPolyDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    poly = reader.GetOutput()
    if poly is None or poly.GetNumberOfPoints() == 0:
        raise InputError("unreadable or empty surface", file=path, expected="VTK XML PolyData with triangles")
    polys = poly.GetPolys()
    offsets = vtk_to_numpy(polys.GetOffsetsArray()).astype(np.int64)
    if np.any(np.diff(offsets) != 3) or poly.GetNumberOfCells() != polys.GetNumberOfCells():
        triangulate = vtkTriangleFilter()
        triangulate.SetInputData(poly)
        triangulate.PassVertsOff()
        triangulate.PassLinesOff()
        triangulate.Update()
        poly = triangulate.GetOutput()
        polys = poly.GetPolys()
    triangles = vtk_to_numpy(polys.GetConnectivityArray()).astype(np.int64).reshape(-1, 3)
    points = vtk_to_numpy(poly.GetPoints().GetData()).astype(np.float64)

    def arrays(data) -> dict[str, np.ndarray]:
        out = {}
        for i in range(data.GetNumberOfArrays()):
            array = data.GetArray(i)
            if array is not None and array.GetName():
                out[array.GetName()] = np.asarray(vtk_to_numpy(array), dtype=np.float64)
        return out

    return SurfaceFrame(points, triangles, arrays(poly.GetPointData()), arrays(poly.GetCellData()))


def write_surface_frame(
    path: str | Path,
    points_mm: np.ndarray,
    triangles: np.ndarray,
    point_data: dict[str, np.ndarray] | None = None,
    cell_data: dict[str, np.ndarray] | None = None,
) -> Path:
    """A .vtp with point and cell arrays (the FE layout of SPEC 9; `edem run` writes cell data only)."""
    from geometries.mesh_io import write_vtp

    write_vtp(path, np.asarray(points_mm, dtype=np.float64), triangles, cell_data, point_data)
    return Path(path)


def non_finite_count(result_dir: str | Path) -> int:
    """Number of NaN/inf values in a result directory: summary numbers, time series, every array.

    The stability campaign requires 0 (SPEC 2-4: no NaN in any output, whatever the input).
    """
    result = read_result_dir(result_dir)
    count = 0

    def walk(value: Any) -> int:
        if isinstance(value, bool):
            return 0
        if isinstance(value, (int, float)):
            return 0 if math.isfinite(value) else 1
        if isinstance(value, dict):
            return sum(walk(v) for v in value.values())
        if isinstance(value, list):
            return sum(walk(v) for v in value)
        return 0

    count += walk(result.summary)
    count += sum(int(np.count_nonzero(~np.isfinite(v))) for v in result.timeseries.values())
    for _, path in result.frames:
        frame = read_surface_frame(path)
        count += int(np.count_nonzero(~np.isfinite(frame.points_mm)))
        for data in (frame.point_data, frame.cell_data):
            count += sum(int(np.count_nonzero(~np.isfinite(v))) for v in data.values())
    return count


def write_static_result_dir(
    out_dir: str | Path,
    *,
    summary: dict[str, Any],
    force_n: np.ndarray,
    displacement_mm: np.ndarray,
    peak_pressure_mpa: float,
    mean_pressure_mpa: float,
    contact_area_mm2: float,
    points_mm: np.ndarray,
    triangles: np.ndarray,
    point_data: dict[str, np.ndarray] | None = None,
    cell_data: dict[str, np.ndarray] | None = None,
    iterations: int = 0,
    force_residual_n: float = 0.0,
) -> Path:
    """A SPEC 9 result directory of one static solution (one time point, t = 0).

    ``summary`` holds the keys that are not derived from the numbers given here (scene, method,
    wall_time_s, warnings and anything specific); the SPEC 9 scalars are filled in. The surface
    (``points_mm``, ``triangles``) carries point and/or cell arrays, as `edem fe` writes them.
    """
    import csv
    import json

    from edem.atomic_dirs import atomic_result_dir
    from edem.results import TIMESERIES_COLUMNS, write_pvd

    force = np.asarray(force_n, dtype=np.float64).reshape(3)
    disp = np.asarray(displacement_mm, dtype=np.float64).reshape(3)
    data = {
        "steps": 1,
        "peak_pressure_mpa": float(peak_pressure_mpa),
        "max_contact_area_mm2": float(contact_area_mm2),
        "final_displacement_mm": [float(x) for x in disp],
        "max_force_residual_n": float(force_residual_n),
        "warnings": [],
        **summary,
    }
    with atomic_result_dir(out_dir) as out:
        (out / "summary.json").write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
        with open(out / "timeseries.csv", "w", newline="", encoding="utf-8") as f:
            writer = csv.writer(f)
            writer.writerow(TIMESERIES_COLUMNS)
            writer.writerow(
                [0, "0.0", *(repr(float(x)) for x in force), repr(float(peak_pressure_mpa)), repr(float(mean_pressure_mpa)),
                 repr(float(contact_area_mm2)), *(repr(float(x)) for x in disp), "0.0", "0.0", "0.0", int(iterations), repr(float(force_residual_n))]
            )
        write_surface_frame(out / "pressure_0000.vtp", points_mm, triangles, point_data, cell_data)
        write_pvd(out / "pressure.pvd", [(0.0, "pressure_0000.vtp")])
    return Path(out_dir)
