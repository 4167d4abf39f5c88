"""Time-dependent loads and joint angles read from a scene's `[load]` and `[kinematics]` tables.

Pure data I/O (README.md#scene-files, scene file): the scene loader hands over already-parsed TOML tables and
the scene file path (for messages and relative paths); this module returns validated float64
arrays. The solver applies them per time point as in docs/method.md#2-edem-the-time-dependent-incremental-method step 1 (place the fixed body by the
joint angle, apply the load T_k). Every bad input raises `InputError` naming the file, the scene
key and what was expected (README.md#scene-files).

Units: time in s, force in N, moment in N·mm, lengths in mm, angles in degrees in files and
scene tables, radians in `JointKinematics.angle_rad`. OpenSim writes moments in N·m: they are
converted to N·mm (x 1000) when read from .sto/.mot unless the table says `moment_unit = "nmm"`.

OpenSim axes are X anterior, Y superior, Z right; the scene's are its own. The file's axes are
never guessed: `axes = "opensim"` (or three signed axis names) maps them onto the scene's, and an
auto-detected JointReaction triple is refused without it (edem.joint_reaction). Columns can also
be picked one by one with `force_columns` / `moment_columns` in scene-axis order, a leading "-"
negating a column.
"""

from __future__ import annotations

import csv
import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from geometries.errors import InputError
from edem.joint_reaction import AXES_PRESETS, JointReactionColumns, axes_matrix
from edem.tables import SceneTable, is_number, not_utf8

NM_TO_NMM = 1000.0
"""N·m -> N·mm."""

LOAD_KEYS = (
    "force_n", "moment_nmm", "time_s", "file", "time_column", "force_columns",
    "moment_columns", "moment_unit", "force_scale", "time_range_s", "frame", "axes", "mobile_body",
    "fixed_body", "max_step_s",
)
"""Keys allowed in the `[load]` table."""

KINEMATICS_KEYS = ("axis_point_mm", "axis_direction", "angle_deg", "file", "angle_column", "time_column")
"""Keys allowed in the `[kinematics]` table."""

_FILE_ONLY_LOAD_KEYS = ("time_column", "force_columns", "moment_columns", "moment_unit")
_CSV_DEFAULT_TIME = "time_s"
_CSV_DEFAULT_FORCE = ("force_x_n", "force_y_n", "force_z_n")
_CSV_DEFAULT_MOMENT = ("moment_x_nmm", "moment_y_nmm", "moment_z_nmm")
_OPENSIM_DEFAULT_TIME = "time"
_OPENSIM_SUFFIXES = (".sto", ".mot")


def _readonly(values: np.ndarray) -> np.ndarray:
    out = np.array(values, dtype=np.float64)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class LoadSeries:
    """Applied load of the mobile body per time point (docs/method.md#2-edem-the-time-dependent-incremental-method step 4: T_k).

    time_s (n,) strictly increasing, force_n (n, 3) in N, moment_nmm (n, 3) in N·mm about the
    reference point G; all finite float64, n >= 1. Arrays are read-only. ``frame`` says in which
    axes the components are given: "global", or "fixed" (the fixed body's axes, so the load turns
    with the joint angle of `[kinematics]`, as a joint reaction expressed in the tibial frame does).
    ``point_mm`` (n, 3), when given, is the point the moment is taken about (in the same frame;
    a JointReaction's joint centre); the solver moves the moment to G. None: about G.
    """

    time_s: np.ndarray
    force_n: np.ndarray
    moment_nmm: np.ndarray
    frame: str = "global"
    point_mm: np.ndarray | None = None
    in_ground: bool = False  # a JointReaction expressed in OpenSim's ground (taken as the scene's axes)
    given_time_s: np.ndarray | None = None  # the times given, when `max_step_s` added points between them

    def __post_init__(self) -> None:
        t = np.asarray(self.time_s, dtype=np.float64)
        f = np.asarray(self.force_n, dtype=np.float64)
        m = np.asarray(self.moment_nmm, dtype=np.float64)
        if t.ndim != 1 or t.size < 1:
            raise ValueError(f"time_s must be a 1-D array with at least one value, got shape {t.shape}")
        n = t.size
        if f.shape != (n, 3) or m.shape != (n, 3):
            raise ValueError(f"force_n and moment_nmm must have shape ({n}, 3), got {f.shape} and {m.shape}")
        if not (np.isfinite(t).all() and np.isfinite(f).all() and np.isfinite(m).all()):
            raise ValueError("load series contains non-finite values")
        if np.any(np.diff(t) <= 0.0):
            raise ValueError("time_s must be strictly increasing")
        if self.frame not in ("global", "fixed"):
            raise ValueError(f"frame must be 'global' or 'fixed', got {self.frame!r}")
        object.__setattr__(self, "time_s", _readonly(t))
        object.__setattr__(self, "force_n", _readonly(f))
        object.__setattr__(self, "moment_nmm", _readonly(m))
        if self.given_time_s is not None:
            object.__setattr__(self, "given_time_s", _readonly(self.given_time_s))
        if self.point_mm is not None:
            p = np.asarray(self.point_mm, dtype=np.float64)
            if p.shape != (n, 3) or not np.isfinite(p).all():
                raise ValueError(f"point_mm must be finite with shape ({n}, 3), got {p.shape}")
            object.__setattr__(self, "point_mm", _readonly(p))


@dataclass(frozen=True, eq=False)
class JointKinematics:
    """Joint rotation of the fixed body per time point (docs/method.md#2-edem-the-time-dependent-incremental-method step 1, README.md#scene-files `[kinematics]`).

    axis_point_mm (3,) a point on the joint axis, axis_direction (3,) unit vector,
    angle_rad (n,) the joint angle at each load time point, in radians.
    """

    axis_point_mm: np.ndarray
    axis_direction: np.ndarray
    angle_rad: np.ndarray

    def __post_init__(self) -> None:
        for name in ("axis_point_mm", "axis_direction", "angle_rad"):
            object.__setattr__(self, name, _readonly(getattr(self, name)))


# --------------------------------------------------------------------------- scene tables


# --------------------------------------------------------------------------- data files


@dataclass
class _DataFile:
    """A numeric table read from a CSV or OpenSim file (values may hold NaN until a column is used)."""

    path: Path
    columns: list[str]
    values: np.ndarray  # (rows, columns)
    line_numbers: list[int]  # 1-based line of each row, for messages
    in_degrees: bool | None  # OpenSim header flag, None when absent or CSV
    key: str  # scene key naming the file, e.g. "load.file"

    def error(self, key: str, problem: str, expected: str | None = None) -> InputError:
        return InputError(problem, file=self.path, key=key, expected=expected)

    def column(self, spec: str, key: str) -> np.ndarray:
        """Column `spec` (leading '-' negates); finite values checked."""
        name, sign = (spec[1:], -1.0) if spec.startswith("-") else (spec, 1.0)
        if name not in self.columns:
            raise self.error(key, f"column '{name}' not found; available columns: {', '.join(self.columns)}",
                             "a column name from the file's header row")
        values = self.values[:, self.columns.index(name)]
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            i = bad[0]
            raise self.error(key, f"value {values[i]} in column '{name}' at line {self.line_numbers[i]}",
                             "finite numbers")
        return sign * values

    def check_converted(self, values: np.ndarray, specs: list[str], key: str, conversion: str, expected: str) -> None:
        """InputError naming the column and line of the first value of ``values`` (one column per
        spec of :meth:`column`) that ``conversion`` made infinite: finite numbers in the file can
        overflow once multiplied (N m -> N mm, m -> mm, a scale)."""
        bad = np.argwhere(~np.isfinite(values))
        if bad.size:
            row, col = (int(i) for i in bad[0])
            name = specs[col].removeprefix("-")
            raise self.error(key, f"{float(self.values[row, self.columns.index(name)])!r} in column '{name}' at line "
                                  f"{self.line_numbers[row]} is not finite after {conversion}", expected)

    def check_time(self, time_s: np.ndarray, key: str) -> None:
        if time_s.size == 0:
            raise self.error(self.key, "no data rows", "at least one row after the header")
        back = np.flatnonzero(np.diff(time_s) <= 0.0)
        if back.size:
            i = back[0] + 1
            raise self.error(key, f"time {time_s[i]} at line {self.line_numbers[i]} does not increase "
                                  f"(previous {time_s[i - 1]})", "strictly increasing time")


def _parse_rows(path: Path, key: str, header: list[str], rows: list[tuple[int, list[str]]],
                in_degrees: bool | None) -> _DataFile:
    """Row-by-row parse: slow, but names the line and column of the first bad value."""
    values = np.empty((len(rows), len(header)))
    for r, (line, fields) in enumerate(rows):
        if len(fields) != len(header):
            raise InputError(f"line {line} has {len(fields)} values but the header has {len(header)} columns",
                             file=path, key=key, expected="one value per header column")
        for c, field in enumerate(fields):
            try:
                values[r, c] = float(field)
            except ValueError:
                raise InputError(f"line {line}, column '{header[c]}': {field!r} is not a number",
                                 file=path, key=key, expected="numbers") from None
    return _DataFile(path, header, values, [line for line, _ in rows], in_degrees, key)


def _read_text(path: Path, key: str) -> list[str]:
    """The lines of a UTF-8 text file; unreadable or non-UTF-8 files are bad input."""
    try:
        return path.read_text(encoding="utf-8").splitlines()
    except UnicodeDecodeError as exc:
        raise InputError(not_utf8(exc), file=path, key=key, expected="a UTF-8 (or ASCII) text file") from None
    except OSError as exc:
        raise InputError(f"cannot read the file: {exc.strerror}", file=path, key=key) from None


def _parse_table(path: Path, key: str, header: list[str], lines: list[tuple[int, str]], delimiter: str | None,
                 split, in_degrees: bool | None) -> _DataFile:
    """Data rows as floats: numpy's C parser for the whole table (1e6 rows in about a second),
    the row-by-row parser only when that fails, to say which line and column is wrong."""
    numbers = [line for _, line in lines]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "empty input": handled by the shape check
            values = np.loadtxt(numbers, delimiter=delimiter, ndmin=2, dtype=np.float64, comments=None)
        if values.shape != (len(numbers), len(header)):
            raise ValueError("column count")
    except ValueError:
        return _parse_rows(path, key, header, [(i, split(line)) for i, line in lines], in_degrees)
    return _DataFile(path, header, values, [i for i, _ in lines], in_degrees, key)


def _read_csv(path: Path, key: str) -> _DataFile:
    """CSV with one header row of column names; blank lines skipped."""
    rows = [(i, line) for i, line in enumerate(_read_text(path, key), start=1) if line.strip(" \t,")]
    if not rows:
        raise InputError("empty file", file=path, key=key, expected="a header row of column names, then data rows")

    def split(line: str) -> list[str]:
        return [f.strip() for f in next(csv.reader([line]))]

    return _parse_table(path, key, split(rows[0][1]), rows[1:], ",", split, None)


def _read_opensim(path: Path, key: str) -> _DataFile:
    """OpenSim .sto/.mot: header lines up to `endheader` (`inDegrees=yes|no` read), then a
    whitespace-separated table whose first row names the columns (`time`, ...)."""
    lines = _read_text(path, key)
    in_degrees: bool | None = None
    end = None
    for i, line in enumerate(lines):
        text = line.strip()
        if text.lower() == "endheader":
            end = i
            break
        name, sep, value = text.partition("=")
        if sep and name.strip().lower() == "indegrees":
            flag = value.strip().lower()
            if flag not in ("yes", "no"):
                raise InputError(f"line {i + 1}: inDegrees={value.strip()}", file=path, key=key,
                                 expected="inDegrees=yes or inDegrees=no")
            in_degrees = flag == "yes"
    if end is None:
        raise InputError("no 'endheader' line", file=path, key=key,
                         expected="an OpenSim storage file: header lines, 'endheader', then a column-name row")
    rows = [(i, line) for i, line in enumerate(lines[end + 1:], start=end + 2) if line.strip()]
    if not rows:
        raise InputError("no column-name row after 'endheader'", file=path, key=key,
                         expected="a row of column names such as 'time\\t...'")
    return _parse_table(path, key, rows[0][1].split(), rows[1:], None, str.split, in_degrees)


def read_opensim_table(path: Path, key: str) -> _DataFile:
    """An OpenSim .sto/.mot as a table (columns, values, the inDegrees flag); InputError naming ``key`` when malformed."""
    return _read_opensim(path, key)


def _read_data_file(path: Path, key: str) -> _DataFile:
    suffix = path.suffix.lower()
    if suffix == ".csv":
        return _read_csv(path, key)
    if suffix in _OPENSIM_SUFFIXES:
        return _read_opensim(path, key)
    raise InputError(f"unsupported file type '{path.suffix}'", file=path, key=key, expected=".csv, .sto or .mot")


def _jointreaction_prefixes(columns: list[str]) -> list[str]:
    """Prefixes p with columns p_fx, p_fy, p_fz all present (OpenSim JointReaction force triples)."""
    return [c[:-3] for c in columns
            if c.endswith("_fx") and c[:-3] + "_fy" in columns and c[:-3] + "_fz" in columns]


# --------------------------------------------------------------------------- [load]


def load_series_from_table(table: dict[str, Any], scene_file: Path) -> LoadSeries:
    """Build the applied load series from a scene's `[load]` table (README.md#scene-files).

    Exactly one of:
    - static: `force_n = [fx, fy, fz]`, optional `moment_nmm = [mx, my, mz]`; one point at t = 0;
    - inline series: `time_s = [...]`, `force_n = [[fx, fy, fz], ...]`, optional `moment_nmm`
      (same length);
    - `file = "path"` (relative to the scene file): CSV with a header row (default columns
      `time_s, force_x_n, force_y_n, force_z_n`, optional `moment_x_nmm, moment_y_nmm,
      moment_z_nmm`), or OpenSim .sto/.mot (default time column `time`). Columns are chosen with
      `time_column`, `force_columns = [3 names]`, `moment_columns = [3 names]`, a leading "-"
      negating a column. For .sto/.mot without `force_columns`, the single JointReaction triple
      `<p>_fx, <p>_fy, <p>_fz` is used with its `<p>_mx, <p>_my, <p>_mz` moments (zero when absent).
      OpenSim moments are N·m and are multiplied by 1000 to N·mm unless `moment_unit = "nmm"`;
      CSV moments are N·mm unless `moment_unit = "nm"`.
    Optional in all forms: `force_scale` (multiplies the force only; default 1),
    `time_range_s = [t0, t1]` (keeps the time points with t0 <= t <= t1) and `max_step_s` (splits
    every longer step into equal ones, the load interpolated linearly; the kinematics follow).
    """
    tab = SceneTable(table, scene_file, "load", LOAD_KEYS)
    scale = tab.number("force_scale", 1.0)
    if tab.has("file") and tab.has("force_n"):
        raise tab.error("file", "both 'file' and 'force_n' are given", "exactly one of 'force_n' or 'file'")
    if tab.has("file"):
        for key in ("time_s", "moment_nmm"):
            if tab.has(key):
                raise tab.error(key, f"'{key}' cannot be combined with 'file'",
                                "column names in time_column / moment_columns instead")
        time_s, force_n, moment_nmm, point_mm, file_frame = _load_from_file(tab, scale)
    elif tab.has("force_n"):
        for key in _FILE_ONLY_LOAD_KEYS:
            if tab.has(key):
                raise tab.error(key, f"'{key}' only applies with 'file'", "no column keys for inline loads")
        time_s, force_n, moment_nmm = _load_inline(tab, scale)
        point_mm, file_frame = None, None
    else:
        raise tab.error("force_n", "no load given", "'force_n' (static or with 'time_s') or 'file'")

    if tab.has("time_range_s"):
        t0, t1 = tab.numbers("time_range_s", 2, "[t0, t1] in s with t0 <= t1")
        if t0 > t1:
            raise tab.error("time_range_s", f"t0 = {t0} > t1 = {t1}", "[t0, t1] with t0 <= t1")
        keep = (time_s >= t0) & (time_s <= t1)
        if not keep.any():
            raise tab.error("time_range_s", f"no time point in [{t0}, {t1}]; the load spans "
                                            f"[{time_s[0]}, {time_s[-1]}] s", "a range containing load time points")
        time_s, force_n, moment_nmm = time_s[keep], force_n[keep], moment_nmm[keep]
        point_mm = None if point_mm is None else point_mm[keep]
    given_time_s = None
    if tab.has("max_step_s"):
        given_time_s = time_s
        time_s = _split_steps(tab, time_s)
        with np.errstate(over="ignore", invalid="ignore"):
            force_n, moment_nmm = _interpolate(given_time_s, force_n, time_s), _interpolate(given_time_s, moment_nmm, time_s)
            point_mm = None if point_mm is None else _interpolate(given_time_s, point_mm, time_s)
        _check_interpolated(tab, given_time_s, time_s, force_n, moment_nmm, point_mm)
    in_ground = file_frame == "ground"
    file_frame = "global" if in_ground else file_frame
    frame = tab.string("frame", file_frame or "global")
    if frame not in ("global", "fixed"):
        raise tab.error("frame", f"'{frame}' is not a frame", "'global' or 'fixed' (the fixed body's axes, turning with [kinematics])")
    if file_frame is not None and frame != file_frame:
        raise tab.error("frame", f"frame = '{frame}' but the file's columns are expressed in the {file_frame} frame",
                        f"frame = '{file_frame}' or no frame key")
    if tab.has("axes"):
        rotation = _axes(tab)
        force_n, moment_nmm = force_n @ rotation.T, moment_nmm @ rotation.T
        point_mm = None if point_mm is None else point_mm @ rotation.T  # (a signed permutation: no sum can overflow)
    return LoadSeries(time_s, force_n, moment_nmm, frame, point_mm, in_ground, given_time_s)


MAX_TIME_POINTS = 100_000
"""More time points than this from `max_step_s` is refused (each is a solve)."""


def _split_steps(tab: SceneTable, time_s: np.ndarray) -> np.ndarray:
    """The given times with every step longer than `max_step_s` split into equal steps (each given
    time kept, so no peak of the load is cut)."""
    step = tab.number("max_step_s", positive=True, what="the longest load step in s (> 0)")
    if time_s.size < 2:
        return time_s
    parts = np.maximum(np.ceil(np.diff(time_s) / step - 1e-9), 1.0)  # 1e-9: a step equal to max_step_s stays whole
    total = float(parts.sum()) + 1.0
    if total > MAX_TIME_POINTS:
        raise tab.error("max_step_s", f"{step:g} s over {time_s[-1] - time_s[0]:g} s makes {total:.0f} time points",
                        f"at most {MAX_TIME_POINTS} time points (a larger max_step_s, or time_range_s)")
    n = parts.astype(int)
    fractions = np.concatenate([np.arange(k) / k for k in n])
    return np.append(np.repeat(time_s[:-1], n) + fractions * np.repeat(np.diff(time_s), n), time_s[-1])


def _check_interpolated(tab: SceneTable, given_time_s: np.ndarray, time_s: np.ndarray, *series: np.ndarray | None) -> None:
    """InputError naming the step whose interpolation overflowed: between two finite values of
    opposite sign near the largest float, their difference is not finite."""
    for values in series:
        if values is not None and not np.all(np.isfinite(values)):
            t = time_s[np.flatnonzero(~np.all(np.isfinite(values), axis=1))[0]]
            k = min(int(np.searchsorted(given_time_s, t)), len(given_time_s) - 1)
            raise tab.error("max_step_s", f"the load interpolated between t = {given_time_s[k - 1]:g} s and t = {given_time_s[k]:g} s "
                                          "is not finite (the values there differ by more than the largest float)",
                            "load values that differ by a finite amount from one time point to the next, or no max_step_s")


def _interpolate(time_s: np.ndarray, values: np.ndarray, new_time_s: np.ndarray) -> np.ndarray:
    """(n, 3) values linearly interpolated column by column onto new_time_s."""
    return np.column_stack([np.interp(new_time_s, time_s, values[:, j]) for j in range(values.shape[1])])


def _axes(tab: SceneTable) -> np.ndarray:
    value = tab.table["axes"]
    try:
        return axes_matrix(value)
    except (ValueError, TypeError) as exc:  # TypeError: neither a preset name nor a list
        raise tab.error("axes", f"{value!r}: {exc}",
                        f"a preset ({', '.join(AXES_PRESETS)}; \"opensim\": file x anterior, y up, z right onto scene x right, "
                        "y anterior, z up) or three signed file axes per scene axis, e.g. [\"z\", \"x\", \"y\"]") from None


def _load_inline(tab: SceneTable, scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    if not tab.has("time_s"):
        force = tab.triple("force_n", "3 finite numbers [fx, fy, fz] (for a series, also give time_s)")
        moment = tab.triple("moment_nmm", "3 finite numbers [mx, my, mz]") if tab.has("moment_nmm") else np.zeros(3)
        return np.zeros(1), _scaled_inline(tab, force[None, :], scale), moment[None, :]
    time_s = tab.numbers("time_s", what="a non-empty list of finite times in s")
    back = np.flatnonzero(np.diff(time_s) <= 0.0)
    if back.size:
        i = back[0] + 1
        raise tab.error("time_s", f"time_s[{i}] = {time_s[i]} does not increase (previous {time_s[i - 1]})",
                        "strictly increasing times")
    n = time_s.size
    force = tab.triples("force_n", n)
    moment = tab.triples("moment_nmm", n) if tab.has("moment_nmm") else np.zeros((n, 3))
    return time_s, _scaled_inline(tab, force, scale), moment


def _scaled_inline(tab: SceneTable, force: np.ndarray, scale: float) -> np.ndarray:
    """force_n times force_scale; InputError naming the first force that overflows."""
    with np.errstate(over="ignore"):
        scaled = force * scale
    bad = np.argwhere(~np.isfinite(scaled))
    if bad.size:
        row, col = (int(i) for i in bad[0])
        where = f"force_n[{row}][{col}]" if tab.has("time_s") else f"force_n[{col}]"
        raise tab.error("force_scale", f"{where} = {force[row, col]!r} N times force_scale = {scale:g} is not finite",
                        "a force_scale that keeps every force finite")
    return scaled


def _load_from_file(tab: SceneTable, scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None, str | None]:
    """time, force (times ``scale``), moment (N mm; file axes), the point the moment is about (mm)
    or None, and the frame the columns are expressed in ("global", "fixed") when the file says
    (JointReaction) or None. Each conversion that overflows is named by file, column and line."""
    path = tab.path("file", "a .csv, .sto or .mot file")
    data = _read_data_file(path, tab.key("file"))
    opensim = path.suffix.lower() in _OPENSIM_SUFFIXES

    time_key = tab.key("time_column") if tab.has("time_column") else tab.key("file")
    time_s = data.column(tab.string("time_column", _OPENSIM_DEFAULT_TIME if opensim else _CSV_DEFAULT_TIME),
                         time_key)
    data.check_time(time_s, time_key)

    moment_names: list[str] | None
    reaction: tuple[float, list[str] | None, str] | None = None  # sign, point columns, frame
    if tab.has("force_columns"):
        force_key = tab.key("force_columns")
        force_names = tab.strings("force_columns", 3)
        moment_names = None
    elif opensim:
        force_key = tab.key("file")
        prefixes = _jointreaction_prefixes(data.columns)
        if len(prefixes) != 1:
            candidates = [c for c in data.columns if c.endswith(("_fx", "_fy", "_fz"))]
            raise data.error(force_key,
                             f"found {len(prefixes)} JointReaction force triples (candidate columns: "
                             f"{', '.join(candidates) or 'none'}; all columns: {', '.join(data.columns)})",
                             "exactly one '<name>_fx, _fy, _fz' triple, or force_columns = [3 names] in [load]")
        p = prefixes[0]
        force_names = [p + "_fx", p + "_fy", p + "_fz"]
        moment_names = [p + "_mx", p + "_my", p + "_mz"]
        reaction = _joint_reaction(tab, data, p)
    else:
        force_key = tab.key("file")
        force_names = list(_CSV_DEFAULT_FORCE)
        moment_names = list(_CSV_DEFAULT_MOMENT)
    with np.errstate(over="ignore"):  # (an overflow is refused just below, naming its line)
        force = np.column_stack([data.column(name, force_key) for name in force_names]) * scale
    data.check_converted(force, force_names, tab.key("force_scale"), f"force_scale = {scale:g}", "a force_scale that keeps every force finite")

    if tab.has("moment_columns"):
        moment_key = tab.key("moment_columns")
        moment_names = tab.strings("moment_columns", 3)
    else:
        moment_key = tab.key("file")
        # default moment columns are optional: used only when all three are present
        if moment_names is not None and not all(name in data.columns for name in moment_names):
            moment_names = None
    moment = (np.column_stack([data.column(name, moment_key) for name in moment_names])
              if moment_names is not None else np.zeros_like(force))

    unit = tab.string("moment_unit", "nm" if opensim else "nmm")
    if unit not in ("nm", "nmm"):
        raise tab.error("moment_unit", f"got {unit!r}", "'nm' (N·m) or 'nmm' (N·mm)")
    if unit == "nm" and moment_names is not None:
        with np.errstate(over="ignore"):
            moment = moment * NM_TO_NMM
        data.check_converted(moment, moment_names, moment_key, "N m -> N mm (x 1000)",
                             f"moments in N m within +-{np.finfo(float).max / NM_TO_NMM:.3g} (finite in N mm)")
    if reaction is None:
        return time_s, force, moment, None, None
    sign, point_names, frame = reaction
    point = None
    if point_names is not None:
        with np.errstate(over="ignore"):
            point = np.column_stack([data.column(name, tab.key("file")) for name in point_names]) * 1000.0  # m -> mm
        data.check_converted(point, point_names, tab.key("file"), "m -> mm (x 1000)",
                             f"joint-centre positions in m within +-{np.finfo(float).max / 1000.0:.3g}")
    return time_s, sign * force, sign * moment, point, frame


def _joint_reaction(tab: SceneTable, data: _DataFile, prefix: str) -> tuple[float, list[str] | None, str]:
    """Sign, the joint-centre columns and the scene frame of an auto-detected JointReaction triple;
    refuses what it cannot place.

    The columns are the load the joint applies *on* ``<body>``. The scene's load is the one pressing
    M into F, which the contact balances: by M's equilibrium, minus the joint's load on M (sign -1);
    by action and reaction, the joint's load on F as is (sign +1). Forces and moments alike: both
    act at the same joint centre, so the moment is negated about that point before it moves to G.
    """
    key = tab.key("file")
    columns = JointReactionColumns.parse(prefix)
    if not tab.has("axes"):
        raise data.error(key, f"the axes of the JointReaction columns '{prefix}_*' are OpenSim's (x anterior, y up, z right) "
                              "and are not guessed",
                         '[load] axes = "opensim" (onto scene x right, y anterior, z up), axes = "same" (meshes in '
                         'OpenSim\'s own axes) or three signed axes, e.g. ["z", "x", "y"]')
    if columns is None:
        return 1.0, None, "global"
    mobile = tab.string("mobile_body") if tab.has("mobile_body") else None
    fixed = tab.string("fixed_body") if tab.has("fixed_body") else None
    if mobile is None:
        raise data.error(key, f"the columns give the load of joint '{columns.joint}' on body '{columns.body}'; "
                              "which body is the scene's mobile one is not said",
                         f"[load] mobile_body = \"{columns.body}\" (and fixed_body = the other) so the load's sign is known")
    if columns.body == mobile:
        sign = -1.0  # the joint holds M back: what presses M into F is the opposite
    elif columns.body == fixed:
        sign = 1.0  # the joint's load on F is what M transmits to F
    else:
        raise data.error(key, f"the load is on body '{columns.body}', neither mobile_body '{mobile}' nor fixed_body '{fixed}'",
                         "a JointReaction of the joint between the scene's two bodies (on_child or on_parent)")
    if columns.frame == fixed:
        frame = "fixed"
    elif columns.frame == mobile:
        frame = "global"  # the scene's frame is M's (M moves only by the solved increments)
    elif columns.frame == "ground":
        frame = "ground"
    else:
        raise data.error(key, f"the load is expressed in frame '{columns.frame}': only the mobile body's frame "
                              f"('{mobile}'), the fixed body's ('{fixed}', turning with the joint) or ground are placed in the scene",
                         "JointReaction express_in_frame = child, parent or ground")
    point_names = columns.names("p")
    return sign, (point_names if all(n in data.columns for n in point_names) else None), frame


# --------------------------------------------------------------------------- [kinematics]


def angle_series_from_table(table: dict[str, Any], scene_file: Path, time_s: np.ndarray,
                            given_time_s: np.ndarray | None = None) -> JointKinematics:
    """Build the joint rotation from a scene's `[kinematics]` table at the load times `time_s`
    (docs/method.md#2-edem-the-time-dependent-incremental-method step 1, README.md#scene-files).

    `axis_point_mm = [x, y, z]`, `axis_direction = [x, y, z]` (normalised; must be non-zero), and
    either `angle_deg` (one value per load time point, or a single value for all) or
    `file = "ik.mot"` (OpenSim .mot/.sto) with `angle_column` (leading "-" negates) and optional
    `time_column` (default `time`). The file's angle is in degrees when its header says
    `inDegrees=yes`, radians when `inDegrees=no`; it is linearly interpolated onto `time_s`,
    which must lie within the file's time range. ``given_time_s``: the load's times before
    `[load] max_step_s` split its steps; inline angles are given at those and interpolated.
    """
    tab = SceneTable(table, scene_file, "kinematics", KINEMATICS_KEYS)
    time_s = np.asarray(time_s, dtype=np.float64).reshape(-1)
    for key in ("axis_point_mm", "axis_direction"):
        if not tab.has(key):
            raise tab.error(key, f"missing '{key}'", "3 finite numbers [x, y, z]")
    axis_point = tab.triple("axis_point_mm")
    axis = tab.triple("axis_direction")
    # Scaled first: the norm of [1e300, 0, 0] overflows, and a subnormal one underflows to zero.
    biggest = float(np.abs(axis).max())
    if biggest == 0.0:
        raise tab.error("axis_direction", "zero vector", "a non-zero direction [x, y, z]")
    axis = axis / biggest
    norm = float(np.linalg.norm(axis))

    if tab.has("file") == tab.has("angle_deg"):
        raise tab.error("angle_deg", "give exactly one of 'angle_deg' or 'file'",
                        "'angle_deg' (list or single value) or 'file' with 'angle_column'")
    if tab.has("angle_deg"):
        for key in ("angle_column", "time_column"):
            if tab.has(key):
                raise tab.error(key, f"'{key}' only applies with 'file'", "no column keys with angle_deg")
        if given_time_s is None:
            angle_deg = _inline_angles(tab, time_s.size)
        else:
            angle_deg = np.interp(time_s, given_time_s, _inline_angles(tab, given_time_s.size))
    else:
        angle_deg = _file_angles(tab, time_s)
    if np.abs(angle_deg).max() > 360.0:  # more than a full turn is no joint angle (a unit or column mix-up)
        key = "angle_deg" if tab.has("angle_deg") else "file"
        worst = angle_deg[np.argmax(np.abs(angle_deg))]
        hint = (f" ({np.radians(worst):g} rad in a file that says inDegrees=no: the values look like degrees)"
                if tab.has("file") else "")
        raise tab.error(key, f"angle {worst:g} deg{hint}",
                        "joint angles within +-360 deg" + (" (inDegrees=yes when the file is in degrees)" if hint else ""))
    return JointKinematics(axis_point, axis / norm, np.deg2rad(angle_deg))


def _inline_angles(tab: SceneTable, n: int) -> np.ndarray:
    value = tab.table["angle_deg"]
    what = f"a number or a list of 1 or {n} numbers (one per load time point)"
    if is_number(value):
        angles = np.array([tab.number("angle_deg")])
    else:
        angles = tab.numbers("angle_deg", what=what)
    if angles.size == 1:
        return np.full(n, angles[0])
    if angles.size != n:
        raise tab.error("angle_deg", f"{angles.size} values for {n} load time points", what)
    return angles


def _file_angles(tab: SceneTable, time_s: np.ndarray) -> np.ndarray:
    path = tab.path("file", "an OpenSim .mot or .sto file")
    if path.suffix.lower() not in _OPENSIM_SUFFIXES:
        raise tab.error("file", f"unsupported file type '{path.suffix}'", "an OpenSim .mot or .sto file")
    if not tab.has("angle_column"):
        raise tab.error("angle_column", "missing 'angle_column'", "the name of the angle column, e.g. 'ankle_angle_r'")
    data = _read_opensim(path, tab.key("file"))
    if data.in_degrees is None:
        raise data.error(tab.key("file"), "no 'inDegrees' header line", "inDegrees=yes or inDegrees=no before endheader")
    time_key = tab.key("time_column") if tab.has("time_column") else tab.key("file")
    file_time = data.column(tab.string("time_column", _OPENSIM_DEFAULT_TIME), time_key)
    data.check_time(file_time, time_key)
    angle = data.column(tab.string("angle_column"), tab.key("angle_column"))
    if not data.in_degrees:
        angle = np.rad2deg(angle)
    tol = 1e-9 * max(1.0, file_time[-1] - file_time[0])
    if time_s.min() < file_time[0] - tol or time_s.max() > file_time[-1] + tol:
        raise data.error(tab.key("file"),
                         f"load times [{time_s.min()}, {time_s.max()}] s fall outside the file's time range "
                         f"[{file_time[0]}, {file_time[-1]}] s", "angle data covering every load time point")
    return np.interp(np.clip(time_s, file_time[0], file_time[-1]), file_time, angle)


# --------------------------------------------------------------------------- stance (docs/references.md#the-thesiss-figures)


def resample_pchip(time_s: np.ndarray, values: np.ndarray, new_time_s: np.ndarray) -> np.ndarray:
    """Shape-preserving piecewise-cubic Hermite (PCHIP) interpolation of `values` (n,) or (n, k)
    from strictly increasing `time_s` onto `new_time_s` (docs/references.md#the-thesiss-figures: the built-in stance is built
    through the 7 published points this way). Passes exactly through the given points and does
    not overshoot: monotone data stay monotone between points. No extrapolation: `new_time_s`
    must lie within [time_s[0], time_s[-1]].
    """
    t = np.asarray(time_s, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    new_t = np.asarray(new_time_s, dtype=np.float64)
    if t.ndim != 1 or t.size < 2 or np.any(np.diff(t) <= 0.0):
        raise ValueError("time_s must be 1-D, strictly increasing, with at least 2 points")
    if v.shape[:1] != t.shape:
        raise ValueError(f"values must have {t.size} rows, got shape {v.shape}")
    if new_t.size and (new_t.min() < t[0] or new_t.max() > t[-1]):
        raise ValueError(f"new_time_s must lie within [{t[0]}, {t[-1]}]")
    # scipy.interpolate takes over a second to import: only scenes with a PCHIP history pay it.
    from scipy.interpolate import PchipInterpolator

    return PchipInterpolator(t, v, axis=0, extrapolate=False)(new_t)


class ThesisStanceTable(NamedTuple):
    """Published stance data (docs/references.md#the-thesiss-figures; thesis section 4.3.4, table 4.3.4.1): ankle angle and
    force on the talus at 7 instants of stance. Only these numbers are published; the 0 % and
    100 % end values of the built-in scene are assumptions stated in its scene file."""

    percent_stance: np.ndarray  # % of stance
    angle_deg: np.ndarray  # ankle angle, degrees
    force_ml_n: np.ndarray  # medio-lateral force on the talus, N
    force_pa_n: np.ndarray  # postero-anterior force on the talus, N
    force_si_n: np.ndarray  # supero-inferior force on the talus, N


def thesis_stance_table() -> ThesisStanceTable:
    """The 7 published stance points of docs/references.md#the-thesiss-figures (table 4.3.4.1), as float64 arrays."""
    rows = np.array([
        # % stance, angle deg, ML N, PA N, SI N
        [12.0, -0.57, 13.64, 21.7, 72.5],
        [20.0, 5.37, 65.25, 143.87, 1071.0],
        [55.0, 10.7, 106.86, -22.14, 2047.0],
        [69.0, 12.92, 158.82, -35.45, 3209.7],
        [78.0, 16.31, 159.94, -52.52, 4078.26],
        [87.0, 17.1, 89.32, -33.88, 3714.94],
        [92.0, 15.1, 28.2, -29.24, 2741.62],
    ])
    return ThesisStanceTable(*(rows[:, j].copy() for j in range(5)))
