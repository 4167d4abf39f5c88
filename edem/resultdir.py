"""The result directory: the one module that writes and reads it (docs/result-format.md).

Every producer writes the same layout through :func:`write_result_dir`. A run of a scene, DEM/EDEM
(:class:`edem.results.RunResult`) or FE (:class:`fem_reference.scene_run.FERunResult`), keeps one
contract, :class:`RunOutput` (its summary, time series rows and frames), and is written by one
writer, :func:`write_run` (under MPI by rank 0 only); the closed forms of
:mod:`verification.closed_forms` and the FE problems of :mod:`verification.fe_analytic` write a
single static solution (:func:`write_static_result_dir`),
and every consumer (``edem compare``, the campaign metrics, the reports) reads it through
:func:`read_result_dir`.

Layout of ``OUT/``:

``summary.json``
    One JSON object. Keys every producer writes: ``scene`` (name), ``method`` (``edem``, ``dem``,
    ``fe-slab``, ``fe-layer``, ``closed-form:<name>``, ``fe-problem:<name>``...), ``steps``
    (time points written), ``wall_time_s``, ``peak_pressure_mpa`` (max over the time points),
    ``max_contact_area_mm2``, ``final_displacement_mm`` (3 floats, of the reference point G),
    ``max_force_residual_n`` and ``warnings`` (list of strings). Written by :func:`write_result_dir`
    from the pressure maps: ``regularised_peak_pressure_mpa`` (the largest over the maps of the
    peak of the pressure averaged over 1 mm^2, :mod:`edem.pressure_metrics`, the judged pressure
    metric; ``peak_pressure_mpa`` is the raw peak, reported only) and its
    ``regularised_peak_pressure_definition``. Usually also
    ``n_springs`` (discrete) or ``n_dofs`` (FE), ``final_rotation_rad``,
    ``max_moment_residual_nmm`` and ``law``; producers add their own keys (FE: element, mesh
    size, strains...; closed forms: ``closed_form``). Every number is finite.
``timeseries.csv``
    A header row, then one row per written time point. The columns are
    :data:`TIMESERIES_COLUMNS` in that order (``iterations``: active-set or Newton iterations),
    then any extra columns a producer adds (readers look columns up by name). Integers as
    integers, floats as Python ``repr`` (exact round trip); every value finite.
``pressure.pvd``
    A ParaView collection: one ``<DataSet timestep=... file="pressure_NNNN.vtp"/>`` per written
    time point (NNNN = the time point's index in the scene's load history). A run written
    without pressure maps (a campaign of hundreds of runs that needs only the time series)
    lists none, and its summary says ``"pressure_maps": 0``; only then may the list be empty.
``pressure_NNNN.vtp``
    VTK XML PolyData (:func:`geometries.mesh_files.write_vtp`): a triangulated surface in mm with
    cell and/or point arrays. Discrete runs and closed forms: the mobile surface at its pose,
    cell data ``pressure_mpa``, ``spring_length_mm``, ``in_contact``, ``ray_hit``. FE runs: the
    FE contact surface with point and cell data ``pressure_mpa`` (and more, see
    :mod:`fem_reference.scene_run`).
``fixed.vtp``
    The fixed body as in the scene (optional).
``scene.toml``
    The resolved scene (:func:`provenance`, passed by every producer of a scene's directory to
    :func:`write_result_dir`): the scene after every override, file paths absolute, its name pinned, the method in
    ``[solver]`` and FE settings in ``[fe]``; ``edem run DIR/scene.toml`` (or ``edem fe``)
    reproduces the run exactly. summary.json then also holds ``overrides`` (dotted keys and
    values), ``scene_source`` (the scene argument as given), ``software_version`` and
    ``source_revision`` (git commit, ``-dirty`` with uncommitted changes; "unknown" outside git).
``fixed.pvd`` + ``fixed_NNNN.vtp``
    The fixed body placed at each time point (optional; discrete runs): open it with
    pressure.pvd in ParaView to see the true relative pose when the fixed body moves.
``timeseries.sto``
    The time series as an OpenSim storage file (optional; discrete runs): ``time`` first, then
    every other column of timeseries.csv under the same name and units; tab separated, the
    header OpenSim's ``TimeSeriesTable`` reads (``version=1``, ``nRows``, ``nColumns``,
    ``inDegrees=no``, ``endheader``).
``manifest.json``
    Every other file (all of the above that were written) with its size and sha256, and the run
    id (:mod:`edem.atomic_dirs`). The directory is written into a temporary sibling and renamed
    into place when complete, so it is never partial; :func:`read_result_dir` refuses one whose
    files do not match their manifest (missing, changed, or left by another run).

To extend the format, change this module only: new summary keys go in the producer's summary
dict, new time-series columns are extra keys of the rows given to :func:`write_result_dir`, new
files are written by :func:`write_result_dir` from new fields of :class:`Frame` or new arguments.
"""

from __future__ import annotations

import csv
import html
import importlib.metadata
import io
import json
import math
import numbers
import subprocess
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from edem.atomic_dirs import ResultFiles, ResultWriteError, atomic_result_dir, verify_manifest
from edem.pressure_metrics import REGULARISED_PEAK_DEFINITION, has_pressure, largest_regularised_peak_mpa, pressure_bound_mpa
from geometries.errors import InputError, SolverError
from geometries.triangle_kernels import triangle_areas

if TYPE_CHECKING:
    from geometries.mesh_files.vtk_family import VtpSeries

SUMMARY_FILE = "summary.json"
TIMESERIES_FILE = "timeseries.csv"
COLLECTION_FILE = "pressure.pvd"
FIXED_FILE = "fixed.vtp"
FIXED_COLLECTION_FILE = "fixed.pvd"
STO_FILE = "timeseries.sto"
#: summary key of a result written without pressure maps (value 0)
MAPS_KEY = "pressure_maps"
#: summary keys of the regularised peak pressure (edem.pressure_metrics), the largest over the
#: written pressure maps, and of what it is, filled in by write_result_dir
REGULARISED_PEAK_KEY, REGULARISED_PEAK_DEFINITION_KEY = "regularised_peak_pressure_mpa", "regularised_peak_pressure_definition"

TIMESERIES_COLUMNS = (
    "step",
    "time_s",
    "force_x_n",
    "force_y_n",
    "force_z_n",
    "peak_pressure_mpa",
    "mean_pressure_mpa",
    "contact_area_mm2",
    "disp_x_mm",
    "disp_y_mm",
    "disp_z_mm",
    "rot_x_rad",
    "rot_y_rad",
    "rot_z_rad",
    "iterations",
    "force_residual_n",
)


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
        return triangle_areas(*(self.points_mm[self.triangles[:, i]] for i in range(3)))


@dataclass(frozen=True)
class Frame:
    """One written time point of pressure.pvd: its index in the load history, time and surface."""

    step: int
    time_s: float
    surface: SurfaceFrame


def timeseries_row(
    step: int,
    time_s: float,
    force_n: Sequence[float],
    peak_pressure_mpa: float,
    mean_pressure_mpa: float,
    contact_area_mm2: float,
    displacement_mm: Sequence[float],
    rotation_rad: Sequence[float],
    iterations: int,
    force_residual_n: float,
) -> dict[str, float]:
    """One timeseries.csv row as {column: value} (:data:`TIMESERIES_COLUMNS`; forces in N,
    pressures in MPa, area in mm^2, displacement of G in mm, rotation vector in rad)."""
    values = [int(step), float(time_s), *np.asarray(force_n, float).reshape(3), float(peak_pressure_mpa),
              float(mean_pressure_mpa), float(contact_area_mm2), *np.asarray(displacement_mm, float).reshape(3),
              *np.asarray(rotation_rad, float).reshape(3), int(iterations), float(force_residual_n)]
    return dict(zip(TIMESERIES_COLUMNS, values))


def write_result_dir(
    out_dir: str | Path,
    summary: Mapping[str, Any],
    timeseries: Sequence[Mapping[str, float]],
    frames: Sequence[Frame],
    fixed: SurfaceFrame | None = None,
    *,
    fixed_frames: Sequence[Frame] = (),
    opensim_sto: bool = False,
    overwrite: bool = False,
    provenance: Provenance | None = None,
    durable: bool = True,
) -> Path:
    """Write a result directory (layout in the module docstring) atomically; returns its path.

    ``timeseries``: one row per time point, {column: value} with at least
    :data:`TIMESERIES_COLUMNS` (:func:`timeseries_row`); extra keys of the first row become extra
    columns. ``frames``: the pressure maps listed in pressure.pvd (none: the summary gets
    ``"pressure_maps": 0``). ``fixed``: the fixed body.
    ``fixed_frames``: the fixed body per time point (fixed.pvd). ``opensim_sto``: also write the
    time series as timeseries.sto. ``overwrite``: replace an existing result directory
    (otherwise InputError). ``provenance``: the resolved scene (scene.toml) and the provenance
    keys of the summary (:func:`provenance`), written with the rest so that an interrupted run
    never leaves a result without them. Every file is written inside one
    :func:`edem.atomic_dirs.atomic_result_dir` (each hashed from the bytes written) and so
    listed in manifest.json; ``durable=False`` skips its fsyncs (a campaign's verified cache
    only).

    Raises SolverError naming the file and key when a number is not finite (a result that
    contradicts itself is never written as if it were one), InputError when the directory
    cannot be written (disk full, read-only...; a previous result there is left unchanged).
    """
    out = Path(out_dir)
    if provenance is not None:
        summary = {**summary, **provenance.summary_keys}
    if not frames:
        summary = {**summary, MAPS_KEY: 0}
    check_finite_summary(summary, out / SUMMARY_FILE)
    columns = list(TIMESERIES_COLUMNS)
    if timeseries:
        columns += [c for c in timeseries[0] if c not in TIMESERIES_COLUMNS]
    lines = []
    for row in timeseries:
        missing = [c for c in columns if c not in row]
        if missing:
            raise ValueError(f"timeseries row {row.get('step')} lacks the column(s) {', '.join(missing)}")
        for column in columns:
            value = row[column]
            if not math.isfinite(float(value)):
                raise SolverError(f"{out / TIMESERIES_FILE}: time point {row['step']}, column '{column}' is not finite ({value})")
        lines.append([_csv_number(row[c]) for c in columns])
    with atomic_result_dir(out, overwrite=overwrite, durable=durable) as files:
        # each map's bound as it is written (one map in memory at a time), then the regularised
        # peak of only the maps whose bound could beat the best found (made again when measured)
        bounds = _write_series(files, "pressure", frames, COLLECTION_FILE, bound=REGULARISED_PEAK_KEY not in summary)
        if bounds:
            positions = list(bounds)
            peak = largest_regularised_peak_mpa(lambda k: frames[positions[k]].surface, list(bounds.values()))
            summary = {**summary, REGULARISED_PEAK_KEY: peak, REGULARISED_PEAK_DEFINITION_KEY: REGULARISED_PEAK_DEFINITION}
            check_finite_summary(summary, out / SUMMARY_FILE)
        files.write(SUMMARY_FILE, json.dumps(dict(summary), indent=2) + "\n")
        if provenance is not None:
            files.write(SCENE_FILE, provenance.scene_toml)
        table = io.StringIO(newline="")
        writer = csv.writer(table)
        writer.writerow(columns)
        writer.writerows(lines)
        files.write(TIMESERIES_FILE, table.getvalue())
        if fixed is not None:
            files.write(FIXED_FILE, surface_frame_text(fixed))
        if fixed_frames:
            _write_series(files, "fixed", fixed_frames, FIXED_COLLECTION_FILE)
        if opensim_sto:
            files.write(STO_FILE, sto_text(columns, [[float(row[c]) for c in columns] for row in timeseries], name=str(summary.get("scene", "edem"))))
    return out


class RunOutput(Protocol):
    """The result contract of a run of a scene, DEM/EDEM or FE: what its directory is written from."""

    scene: Any  # edem.scene.Scene: its fixed body is fixed.vtp
    #: also write the time series as timeseries.sto
    opensim_sto: bool

    def summary(self) -> dict[str, Any]:
        """summary.json: the keys every producer writes (module docstring) and its own."""
        ...

    def timeseries_rows(self) -> list[dict[str, float]]:
        """timeseries.csv, one row per time point: :func:`timeseries_row`'s columns, then extra ones."""
        ...

    def frames(self, positions: Sequence[int] | None = None) -> Sequence[Frame]:
        """The pressure maps of the time points at ``positions`` in the run (default: all); the
        writer reads each in order, then again the few whose regularised peak it measures (a
        sequence may make each map when it is read)."""
        ...

    def fixed_frames(self, positions: Sequence[int] | None = None) -> Sequence[Frame]:
        """The fixed body placed at those time points (fixed.pvd; empty: not written)."""
        ...


class Communicator(Protocol):
    """What :func:`write_run` needs of an MPI communicator (mpi4py's ``Comm``)."""

    rank: int

    def bcast(self, value: Any, root: int = 0) -> Any: ...


def write_run(
    run: RunOutput,
    out_dir: str | Path,
    *,
    frame_steps: Sequence[int] | None = None,
    note: str | None = None,
    overwrite: bool = False,
    provenance: Provenance | None = None,
    durable: bool = True,
    time_series_only: bool = False,
    comm: Communicator | None = None,
) -> Path:
    """Write a run's result directory (:func:`write_result_dir`) from its :class:`RunOutput`.

    ``frame_steps``: positions in the run whose maps are written (default: all); ``note``: the
    summary's ``frames`` entry when only some are; ``time_series_only``: no surface at all and no
    timeseries.sto. ``comm``: under MPI, only rank 0 writes, and every rank learns whether it
    worked, raising the same error (no rank waits for ever on one that failed); None: this process
    writes. Errors as :func:`write_result_dir`.
    """
    if comm is None:
        return _write_run(run, out_dir, frame_steps, note, overwrite, provenance, durable, time_series_only)
    failure = None
    if comm.rank == 0:
        try:
            _write_run(run, out_dir, frame_steps, note, overwrite, provenance, durable, time_series_only)
        except ResultWriteError as exc:  # disk full, not writable
            failure = ("write", exc.problem)
        except InputError as exc:  # a result there already
            failure = ("input", exc.problem)
        except OSError as exc:
            failure = ("input", f"cannot write the result directory: {exc}")
        except Exception as exc:
            failure = ("solver", f"writing the result directory failed: {exc}")
    failure = comm.bcast(failure, root=0)
    if failure is not None:
        if failure[0] == "write":
            raise ResultWriteError(failure[1], file=str(out_dir), expected="free space and a writable directory (--out)")
        if failure[0] == "input":
            raise InputError(failure[1], file=str(out_dir), expected="a writable directory (--out)")
        raise SolverError(failure[1])
    return Path(out_dir)


def _write_run(run: RunOutput, out_dir: str | Path, frame_steps: Sequence[int] | None, note: str | None, overwrite: bool,
               provenance: Provenance | None, durable: bool, time_series_only: bool) -> Path:
    data = run.summary()
    if note is not None:
        data["frames"] = note
    if time_series_only:
        frames, fixed, fixed_frames = [], None, []
    else:
        frames, fixed_frames = run.frames(frame_steps), run.fixed_frames(frame_steps)
        fixed = SurfaceFrame(run.scene.fixed.vertices_mm, run.scene.fixed.triangles, {}, run.scene.fixed_cell_data())
    return write_result_dir(out_dir, data, run.timeseries_rows(), frames, fixed, fixed_frames=fixed_frames,
                            opensim_sto=run.opensim_sto and not time_series_only, overwrite=overwrite, provenance=provenance, durable=durable)


def _write_series(files: ResultFiles, prefix: str, frames: Iterable[Frame], collection: str, *, bound: bool = False) -> dict[int, float]:
    """<prefix>_NNNN.vtp per frame and the ParaView collection listing them; with ``bound``, the
    :func:`edem.pressure_metrics.pressure_bound_mpa` of each frame that has a pressure
    (:func:`edem.pressure_metrics.has_pressure`), by its position in ``frames``."""
    from geometries.mesh_files.vtk_family import VtpSeries

    entries, bounds = [], {}
    series = VtpSeries()  # the frames' mesh and unchanged arrays, encoded once
    for position, frame in enumerate(frames):
        name = f"{prefix}_{frame.step:04d}.vtp"
        files.write(name, surface_frame_text(frame.surface, series=series))
        entries.append((float(frame.time_s), name))
        if bound and has_pressure(frame.surface):
            bounds[position] = pressure_bound_mpa(frame.surface)
    files.write(collection, pvd_text(entries))
    return bounds


def sto_text(columns: Sequence[str], rows: Sequence[Sequence[float]], *, name: str = "edem") -> str:
    """An OpenSim storage (.sto) file's content: ``time`` (from the ``time_s`` column) first, then
    the other columns; every value written with ``repr`` (exact round trip). Values must be finite."""
    columns = list(columns)
    order = [columns.index("time_s")] + [i for i, c in enumerate(columns) if c != "time_s"]
    labels = ["time"] + [columns[i] for i in order[1:]]
    lines = [name, "version=1", f"nRows={len(rows)}", f"nColumns={len(labels)}", "inDegrees=no", "endheader", "\t".join(labels)]
    lines += ["\t".join(repr(float(row[i])) for i in order) for row in rows]
    return "\n".join(lines) + "\n"


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
    """A result directory of one static solution (one time point, t = 0).

    ``summary`` holds the keys that are not derived from the numbers given here (scene, method,
    wall_time_s, warnings and anything specific); the common scalars are filled in. The surface
    (``points_mm`` (n, 3) mm, ``triangles`` (m, 3)) carries point and/or cell arrays.
    """
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
    row = timeseries_row(0, 0.0, force_n, peak_pressure_mpa, mean_pressure_mpa, contact_area_mm2, disp, np.zeros(3), iterations, force_residual_n)
    surface = SurfaceFrame(np.asarray(points_mm, dtype=np.float64), triangles, point_data or {}, cell_data or {})
    return write_result_dir(out_dir, data, [row], [Frame(0, 0.0, surface)])


def _csv_number(x: Any) -> str:
    if type(x) is float:  # nearly every value (timeseries_row's); the ABC check below costs 4x the repr
        return repr(x)
    return str(int(x)) if isinstance(x, numbers.Integral) else repr(float(x))


def check_finite_summary(summary: Mapping[str, Any], file: str | Path = SUMMARY_FILE) -> None:
    """SolverError naming the key when a top-level number (or list of numbers) is NaN or inf."""
    for key, value in summary.items():
        values = value if isinstance(value, list) else [value]
        if any(isinstance(v, float) and not math.isfinite(v) for v in values):
            raise SolverError(f"{file}: summary value {key} is not finite: {value}")


def pvd_text(entries: list[tuple[float, str]]) -> str:
    """A ParaView collection file's content, listing one dataset (time value, file name) per entry."""
    lines = ['<?xml version="1.0"?>', '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">', "  <Collection>"]
    lines += [f'    <DataSet timestep="{t!r}" part="0" file="{html.escape(name, quote=True)}"/>' for t, name in entries]
    lines += ["  </Collection>", "</VTKFile>", ""]
    return "\n".join(lines)


def write_pvd(path: Path, entries: list[tuple[float, str]]) -> None:
    """A ParaView collection file listing one dataset per time value (:func:`pvd_text`)."""
    Path(path).write_text(pvd_text(entries), encoding="utf-8")


def write_surface_frame(
    path: str | Path,
    points_mm: np.ndarray,
    triangles: np.ndarray,
    point_data: dict[str, np.ndarray] | None = None,
    cell_data: dict[str, np.ndarray] | None = None,
) -> Path:
    """A .vtp with point and cell arrays (the FE layout; discrete runs write cell data only)."""
    from geometries.mesh_files import write_vtp

    write_vtp(path, np.asarray(points_mm, dtype=np.float64), triangles, cell_data, point_data)
    return Path(path)


def surface_frame_text(surface: SurfaceFrame, *, series: VtpSeries | None = None) -> str:
    """The .vtp content of a surface frame (:func:`geometries.mesh_files.vtp_text`); ``series``:
    the :class:`geometries.mesh_files.vtk_family.VtpSeries` of the files of a run's time points
    (what they share encoded once)."""
    from geometries.mesh_files import vtp_text

    return vtp_text(np.asarray(surface.points_mm, dtype=np.float64), surface.triangles, surface.cell_data, surface.point_data, series=series)


# --------------------------------------------------------------------------------------------
# reading


@dataclass(frozen=True)
class ResultDir:
    """A result directory as read: summary, time series columns and one surface file per time."""

    path: Path
    summary: dict[str, Any]
    timeseries: dict[str, np.ndarray]  # column -> (n_times,) float
    frames: tuple[tuple[float, Path], ...]  # (time_s, .vtp path) from pressure.pvd

    @property
    def time_s(self) -> np.ndarray:
        return self.timeseries["time_s"]

    def frame(self, index: int) -> SurfaceFrame:
        if not self.frames:
            raise InputError("the result was written without pressure maps", file=self.path / COLLECTION_FILE,
                             expected="a run that writes them (campaign option frames = \"all\" or \"peak\")")
        return read_surface_frame(self.frames[index][1])


def read_result_dir(path: str | Path) -> ResultDir:
    """Read summary.json, timeseries.csv and the pressure.pvd index of a result directory.

    Raises InputError naming the file when something of the layout is missing or unreadable,
    and when the directory does not verify against its manifest (a file missing, changed or
    left by another run: :func:`edem.atomic_dirs.verify_manifest`).
    """
    root = Path(path)
    expected = "a result directory of edem run / edem fe (summary.json, timeseries.csv, pressure.pvd)"
    if not root.is_dir():
        raise InputError("not a directory", file=root, expected=expected)
    if not (root / SUMMARY_FILE).is_file():
        raise InputError("no summary.json here", file=root, expected=expected)
    verify_manifest(root)
    try:
        summary = json.loads((root / SUMMARY_FILE).read_text(encoding="utf-8"))
    except ValueError as exc:
        raise InputError(f"summary.json is not valid JSON: {exc}", file=root / SUMMARY_FILE) from None
    series = read_timeseries_csv(root / TIMESERIES_FILE)
    pvd = root / COLLECTION_FILE
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
    if not frames and not (isinstance(summary, dict) and summary.get(MAPS_KEY) == 0):
        raise InputError("pressure.pvd lists no data set", file=pvd, expected="one <DataSet> per time point")
    return ResultDir(root, summary, series, frames)


def read_timeseries_csv(path: str | Path) -> dict[str, np.ndarray]:
    """Columns of a timeseries.csv as float arrays."""
    path = Path(path)
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = list(csv.reader(f))
    except FileNotFoundError:
        raise InputError("no timeseries.csv here", file=path.parent, expected="a result directory (docs/result-format.md)") from None
    if not rows:
        raise InputError("empty timeseries.csv", file=path, expected="a header and one row per time point")
    header = rows[0]
    try:
        data = np.array(rows[1:], dtype=float).reshape(-1, len(header))
    except ValueError:
        raise InputError("timeseries.csv has non-numeric or ragged rows", file=path, expected="numbers, one per column") from None
    if "time_s" not in header:
        raise InputError("timeseries.csv has no time_s column", file=path, expected="the docs/result-format.md columns")
    return {name: data[:, i] for i, name in enumerate(header)}


def read_surface_frame(path: str | Path) -> SurfaceFrame:
    """Points, triangles and the point/cell arrays of a .vtp (polygons fan-triangulated by VTK)."""
    from geometries.mesh_files.vtk_family import load_vtk

    load_vtk("reading a result's pressure maps (.vtp)")
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


def non_finite_count(result_dir: str | Path) -> int:
    """Number of NaN/inf values in a result directory: summary numbers, time series, every array.

    The stability campaign requires 0 (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs, docs/method.md#2-edem-the-time-dependent-incremental-method, docs/method.md#4-viscoelastic-edem-thesis-chapter-6: no NaN in any output, whatever the input).
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


# ---------------------------------------------------------------------------------------------
# Provenance: what makes a scene's result directory reproducible

SOURCE_ROOT = Path(__file__).resolve().parents[1]
SCENE_FILE = "scene.toml"
#: scene keys that name files, relative to the scene file: (section, key)
FILE_KEYS = (("geometry", "mobile"), ("geometry", "fixed"), ("geometry", "mobile_bone"), ("geometry", "fixed_bone"), ("load", "file"), ("kinematics", "file"))


@lru_cache(maxsize=1)
def software_version() -> str:
    """The installed ``edem`` package version ("unknown" when it is not installed); read once per
    process (a campaign worker writes hundreds of result directories)."""
    try:
        return importlib.metadata.version("edem")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


@lru_cache(maxsize=1)
def source_revision() -> str:
    """The git commit of the source tree (``-dirty`` when it has uncommitted changes), or "unknown"."""
    def git(*args: str) -> str:
        return subprocess.run(["git", "-C", str(SOURCE_ROOT), *args], capture_output=True, text=True, check=True, timeout=20).stdout.strip()

    try:
        commit = git("rev-parse", "HEAD")
        dirty = git("status", "--porcelain", "--untracked-files=no", "--", "edem", "geometries", "fem_reference", "verification", "reports")
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return commit + ("-dirty" if dirty else "") if commit else "unknown"


def resolved_scene(scene_ref: str | Path, overrides: dict[str, Any] | None = None, fe_settings: dict[str, Any] | None = None,
                   method: str | None = None) -> dict[str, Any]:
    """The scene's TOML data after ``overrides``, file paths made absolute, its name pinned.

    ``fe_settings`` (model, mesh_size_mm, degree, element, layers_through_thickness) are written into ``[fe]``, ``method`` (a
    ``--method`` given on the command line) into ``[solver]``. Overrides must
    already be plain dotted keys (``verification.sides.expand_array_overrides`` expands the
    ``array[*].key`` form).
    """
    from edem.scene import apply_overrides, read_scene_toml, resolve_scene_path

    path = resolve_scene_path(scene_ref)
    data = read_scene_toml(path)
    if overrides:
        apply_overrides(data, dict(overrides))
    meta = data.setdefault("scene", {})
    meta.setdefault("name", path.stem)  # the resolved file is called scene.toml: keep the scene's own name
    for section, key in FILE_KEYS:
        value = data.get(section, {}).get(key) if isinstance(data.get(section), dict) else None
        if isinstance(value, str):
            data[section][key] = str((path.parent / value).resolve())
    if method:
        data.setdefault("solver", {})["method"] = method
    if fe_settings:
        data.setdefault("fe", {}).update({k: v for k, v in fe_settings.items() if v is not None})
    return data


@dataclass(frozen=True)
class Provenance:
    """What reproduces a run: the resolved scene as TOML text and the summary keys that say where
    it came from (overrides, scene_source, software_version, source_revision)."""

    scene_toml: str
    summary_keys: dict[str, Any]


def provenance(scene_ref: str | Path, overrides: dict[str, Any] | None = None, fe_settings: dict[str, Any] | None = None,
               method: str | None = None) -> Provenance:
    """The :class:`Provenance` of a run of ``scene_ref`` (arguments as :func:`resolved_scene`)."""
    import tomli_w

    return Provenance(
        tomli_w.dumps(resolved_scene(scene_ref, overrides, fe_settings, method)),
        dict(overrides=dict(overrides or {}), scene_source=str(scene_ref), software_version=software_version(),
             source_revision=source_revision()),
    )
