"""Seeded fuzz of the `edem run` command line (issue 13): hostile input ends in exit 0 or 2.

A few hundred mutations of small scenes, their load files (CSV and OpenSim .sto) and their mesh
files (OBJ): values swapped for huge integers, non-finite numbers, wrong types, deep nesting,
non-UTF-8 bytes, truncation, bad paths and names; and the coupled thin layer's keys at the ends
of their ranges on the unmutated scenes; and byte-wise mutations of the mesh files in every
format a scene reads (STL, PLY, VTK, VTU, VTP). Each case runs the CLI's ``main`` in-process
(a handful through a real subprocess) and must end with status 0 or 2 (never an uncaught
exception), with a message on stderr for status 2 and no NaN in any file written.
"""

from __future__ import annotations

import contextlib
import io
import os
import random
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from edem.cli import main
from geometries.mesh_files import read_surface, write_surface

ROOT = Path(__file__).resolve().parents[2]
N_CASES = 300  # ~0.1 s each in-process on the CI machine: well under a minute
SEED = 13

SCENE_CSV = """[scene]
name = "fuzz-csv"

[geometry]
builtin = "flat_plates"
width_mm = 10.0
depth_mm = 10.0
gap_mm = 2.0
n_per_side = 4

[cartilage]
youngs_modulus_mpa = 10.35
poissons_ratio = 0.42
law = "threshold"
max_spring_length_mm = 3.5

[load]
file = "load.csv"

[constraints]
fixed_dofs = ["tx", "ty", "rx", "ry", "rz"]

[solver]
method = "edem"
"""

SCENE_MESH = """[scene]
name = "fuzz-mesh"

[geometry]
mobile = "mobile.obj"
fixed = "fixed.obj"

[cartilage]
youngs_modulus_mpa = 10.35
poissons_ratio = 0.42
max_spring_length_mm = 3.5
shear_modulus_mpa = 0.5

[load]
file = "load.sto"
moment_unit = "nmm"
axes = "same"

[kinematics]
axis_point_mm = [0.0, 0.0, 0.0]
axis_direction = [1.0, 0.0, 0.0]
angle_deg = [0.0, 0.5, 1.0]

[solver]
method = "edem"
"""

LOAD_CSV = "time_s,force_x_n,force_y_n,force_z_n\n0.0,0,0,100\n0.1,0,0,200\n0.2,0,0,300\n"
LOAD_STO = "version=1\ninDegrees=no\nendheader\ntime\tj_fx\tj_fy\tj_fz\n0.0\t0\t0\t100\n0.1\t1\t0\t200\n0.2\t0\t1\t300\n"


def _plate_obj(z: float, n: int, facing_up: bool) -> str:
    x = np.linspace(-5.0, 5.0, n + 1)
    lines = [f"v {a:.6g} {b:.6g} {z:.6g}" for a in x for b in x]
    for i in range(n):
        for j in range(n):
            a, b, c, d = i * (n + 1) + j + 1, (i + 1) * (n + 1) + j + 1, (i + 1) * (n + 1) + j + 2, i * (n + 1) + j + 2
            tris = [(a, b, c), (a, c, d)] if facing_up else [(a, c, b), (a, d, c)]
            lines += [f"f {p} {q} {r}" for p, q, r in tris]
    return "\n".join(lines) + "\n"


BASE_FILES = {
    "csv": {"scene.toml": SCENE_CSV, "load.csv": LOAD_CSV},
    "mesh": {
        "scene.toml": SCENE_MESH,
        "load.sto": LOAD_STO,
        "mobile.obj": _plate_obj(0.0, 4, True),
        "fixed.obj": _plate_obj(2.0, 5, False),
    },
}

HOSTILE_VALUES = [
    "10**400", "-10**400", "1e308", "-1e308", "nan", "inf", "-inf", "0", "-1", "1e-320", '"abc"',
    '"\u00fc\u00f1\u00ee"', "[]", "[1, 2]", "[[1, 2, 3]]", "{}", "true", '""', "[" * 3000 + "]" * 3000, "1e300", "1e-300", "5e-324", "1e-9", "1e9",
    '"' + "x" * 5000 + '"', "[1e400, 0, 0]", "[0, 0, 1e300]", "[0, 0, -1e300]", '"../../etc/passwd"',
]
HOSTILE_CELLS = ["nan", "inf", "-inf", "1e400", "1" + "0" * 400, "abc", "", "1,2", "\u00ff", "0x10", "1e-400"]


def _mutate_toml(text: str, rng: random.Random) -> str:
    lines = text.splitlines()
    keyed = [i for i, line in enumerate(lines) if "=" in line and not line.startswith("[")]
    i = rng.choice(keyed)
    key = lines[i].split("=")[0].strip()
    choice = rng.random()
    if choice < 0.6:
        lines[i] = f"{key} = {rng.choice(HOSTILE_VALUES).replace('10**400', '1' + '0' * 400)}"
    elif choice < 0.75:
        del lines[i]
    elif choice < 0.85:
        lines.insert(i, f"{rng.choice(['bogus', 'youngs_modulus', 'f\u00f6rce_n', 'x' * 300])} = 1")
    else:
        section = rng.choice([line for line in lines if line.startswith("[")])
        lines.remove(section)
    return "\n".join(lines) + "\n"


def _mutate_table(text: str, rng: random.Random) -> str:
    lines = text.splitlines()
    data = [i for i, line in enumerate(lines) if line and (line[0].isdigit() or line[0] == "-")]
    i = rng.choice(data)
    sep = "," if "," in lines[i] else "\t"
    cells = lines[i].split(sep)
    choice = rng.random()
    if choice < 0.6:
        cells[rng.randrange(len(cells))] = rng.choice(HOSTILE_CELLS)
        lines[i] = sep.join(cells)
    elif choice < 0.75:
        lines[i] = sep.join(cells[:-1])
    elif choice < 0.9:
        lines.insert(i + 1, lines[i])  # repeated time
    else:
        lines = lines[: rng.randrange(len(lines))]
    return "\n".join(lines) + "\n"


def _mutate_obj(text: str, rng: random.Random) -> str:
    lines = text.splitlines()
    i = rng.randrange(len(lines))
    parts = lines[i].split()
    choice = rng.random()
    if choice < 0.5:
        parts[rng.randrange(1, len(parts))] = rng.choice(["inf", "nan", "1e300", "-1e300", "99999", "0", "-5", "abc"])
        lines[i] = " ".join(parts)
    elif choice < 0.7:
        lines = lines[:i]
    elif choice < 0.85:
        lines = [line for line in lines if line.startswith("v ")]  # no faces at all
    else:
        lines = [lines[0]] * len(lines)  # every vertex the same: zero-area faces
    return "\n".join(lines) + "\n"


def _corrupt_bytes(data: bytes, rng: random.Random) -> bytes:
    if rng.random() < 0.5:
        at = rng.randrange(len(data))
        return data[:at] + bytes([rng.choice([0xFF, 0xFE, 0xC3, 0x80, 0x00])]) + data[at:]
    return data[: rng.randrange(len(data))]


def _case(rng: random.Random, root: Path) -> list[str]:
    """Write one mutated case under `root` and return its argv."""
    base = rng.choice(list(BASE_FILES))
    files = {name: text.encode("utf-8") for name, text in BASE_FILES[base].items()}
    target = rng.choice(list(files))
    text = files[target].decode("utf-8")
    kind = rng.random()
    if kind < 0.15:
        files[target] = _corrupt_bytes(files[target], rng)
    elif target == "scene.toml":
        files[target] = _mutate_toml(text, rng).encode("utf-8")
    elif target.endswith(".obj"):
        files[target] = _mutate_obj(text, rng).encode("utf-8")
    else:
        files[target] = _mutate_table(text, rng).encode("utf-8")
    root.mkdir(parents=True)
    for name, data in files.items():
        (root / name).write_bytes(data)
    out = root / "out"
    extra: list[str] = []
    special = rng.random()
    if special < 0.04:
        out.write_text("a file where the output directory should go")
    elif special < 0.07:
        out = root / ("n" * 300)
    elif special < 0.10:
        extra = ["--set", rng.choice(["cartilage.poissons_ratio=0.5", "load.force_scale=1e308", "scene.name=" + "y" * 300, "geometry.mobile=" + "z" * 300,
                                      "cartilage.youngs_modulus_mpa=1" + "0" * 400, "geometry.units=m"])]
    return ["run", str(root / "scene.toml"), "--out", str(out), *extra]


# The coupled thin layer's keys (issue 10) at the ends of their ranges, set on the unmutated
# bases: a fuzz of these found a LinAlgError in the coupled gap-log layer's weak-DOF check.
COUPLED_SETTINGS = {
    "cartilage.thin_layer_symbol": ['"pade"', '"two-pole"'],
    "cartilage.poissons_ratio": ["0", "0.1", "0.45", "0.499", "0.4999999", "-0.999"],
    "cartilage.law": ['"threshold"', '"gap"', '"gap-log"'],
    "cartilage.thickness_mm": ["1e-9", "1.0", "2.0"],
    "load.force_scale": ["1", "1000", "1e6"],
    "solver.method": ['"dem"', '"edem"'],
    "viscoelastic.relaxation_time_s": ["1e-6", "0.1"],
    # coarse cells of 0.5 smoothing lengths coarsen even the small bases; 1e9 never does
    "cartilage.thin_layer_smoothing_resolution": ["0", "0.5", "3", "1e9"],
}
N_COUPLED_CASES = 80


def _coupled_case(rng: random.Random, root: Path) -> list[str]:
    """Write an unmutated base under `root` and return its argv with the coupled layer on."""
    root.mkdir(parents=True)
    for name, text in BASE_FILES[rng.choice(list(BASE_FILES))].items():
        (root / name).write_text(text)
    settings = ['cartilage.coupling="thin-layer"'] + [f"{key}={rng.choice(values)}" for key, values in COUPLED_SETTINGS.items() if rng.random() < 0.6]
    return ["run", str(root / "scene.toml"), "--out", str(root / "out"), *(a for s in settings for a in ("--set", s))]


# Every mesh format a scene reads (binary STL beside the lossless ascii one), mutated byte-wise:
# this fuzz found a segfault in VTK's walk of corrupted legacy cell offsets and an endless loop
# in meshio's reader of a PLY header cut short.
MESH_FORMATS = (".stl", ".ply", ".vtk", ".vtu", ".vtp", "-binary.stl")
N_MESH_CASES = 120


def _flip_bytes(data: bytes, rng: random.Random) -> bytes:
    flipped = bytearray(data)
    for _ in range(rng.randint(1, 8)):
        flipped[rng.randrange(len(flipped))] = rng.randrange(256)
    return bytes(flipped)


def _write_mesh_case(root: Path, fmt: str, files: dict[str, bytes]) -> list[str]:
    """The mesh base's scene and load under ``root`` with its bodies ``files`` in format ``fmt``; its argv."""
    root.mkdir(parents=True)
    for name, data in files.items():
        (root / name).write_bytes(data)
    (root / "load.sto").write_text(LOAD_STO)
    (root / "scene.toml").write_text(SCENE_MESH.replace('"mobile.obj"', f'"mobile{fmt}"').replace('"fixed.obj"', f'"fixed{fmt}"'))
    return ["run", str(root / "scene.toml"), "--out", str(root / "out")]


def _mesh_case(rng: random.Random, root: Path, bases: dict[str, dict[str, bytes]]) -> list[str]:
    """The mesh base with both bodies in one format, one of them mutated."""
    fmt = rng.choice(MESH_FORMATS)
    files = {f"{body}{fmt}": data for body, data in bases[fmt].items()}
    victim = rng.choice(list(files))
    files[victim] = rng.choice([_corrupt_bytes, _flip_bytes])(files[victim], rng)
    return _write_mesh_case(root, fmt, files)


def _mesh_bases(root: Path) -> dict[str, dict[str, bytes]]:
    """The mesh base's two plates written in every format of MESH_FORMATS: format -> body -> bytes."""
    root.mkdir()
    bases: dict[str, dict[str, bytes]] = {}
    for body in ("mobile", "fixed"):
        (root / f"{body}.obj").write_text(BASE_FILES["mesh"][f"{body}.obj"])
        surface = read_surface(root / f"{body}.obj")
        for fmt in MESH_FORMATS:
            path = root / f"{body}{fmt}"
            write_surface(path, surface, binary=True if fmt == "-binary.stl" else None)
            bases.setdefault(fmt, {})[body] = path.read_bytes()
    return bases


def _run_in_process(argv: list[str]) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        status = main(argv)
    return status, err.getvalue()


def _written_nan(out: Path) -> list[str]:
    bad = []
    try:
        is_dir = out.is_dir()
    except OSError:  # a name too long for the file system: nothing was written
        is_dir = False
    if is_dir:
        for path in out.rglob("*"):
            if path.suffix in (".json", ".csv") and re.search(r"\bnan\b", path.read_text(errors="replace"), re.IGNORECASE):
                bad.append(str(path))
    return bad


@pytest.mark.parametrize("base", sorted(BASE_FILES))
def test_unmutated_fuzz_bases_solve(tmp_path, base):
    """The scenes the fuzz mutates are valid: their refusals are caused by the mutations."""
    for name, text in BASE_FILES[base].items():
        (tmp_path / name).write_text(text)
    status, err = _run_in_process(["run", str(tmp_path / "scene.toml"), "--out", str(tmp_path / "out")])
    assert status == 0, err


def _failures(cases) -> list[str]:
    """What went wrong in each (number, argv) case: an escaped exception, a status other than 0 or
    2, a silent status 2, or NaN written."""
    failures: list[str] = []
    for n, argv in cases:
        try:
            status, err = _run_in_process(argv)
        except BaseException as exc:  # noqa: BLE001 - any escape is what the test looks for
            failures.append(f"case {n}: {type(exc).__name__}: {str(exc)[:200]}")
            continue
        if status not in (0, 2) or (status == 2 and not err.strip()):
            failures.append(f"case {n}: status {status}, stderr {err[:200]!r}")
        nan_files = _written_nan(Path(argv[3]))
        if nan_files:
            failures.append(f"case {n}: NaN written in {nan_files}")
    return failures


def test_fuzzed_scenes_load_files_and_meshes_exit_0_or_2_without_traceback_or_nan(tmp_path):
    rng = random.Random(SEED)
    failures = _failures((n, _case(rng, tmp_path / f"case{n:03d}")) for n in range(N_CASES))
    assert not failures, "\n".join(failures)


def test_coupled_layer_settings_at_their_range_ends_exit_0_or_2_without_traceback_or_nan(tmp_path):
    rng = random.Random(SEED)
    failures = _failures((n, _coupled_case(rng, tmp_path / f"case{n:03d}")) for n in range(N_COUPLED_CASES))
    assert not failures, "\n".join(failures)


@pytest.mark.parametrize("n", range(4))
def test_fuzzed_cases_through_a_real_process_print_no_traceback(tmp_path, n):
    """The same cases through `python -m edem` (what a user runs): no traceback on stderr."""
    rng = random.Random(SEED + 1000 + n)
    argv = _case(rng, tmp_path / "case")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, "-m", "edem", *argv], capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode in (0, 2), proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr, proc.stderr[-2000:]


def test_mutated_mesh_files_of_every_format_exit_0_or_2_without_traceback_or_nan(tmp_path):
    bases = _mesh_bases(tmp_path / "bases")
    for fmt in MESH_FORMATS:  # unmutated, the base solves in every format
        status, err = _run_in_process(_write_mesh_case(tmp_path / f"base{fmt}", fmt, {f"{b}{fmt}": d for b, d in bases[fmt].items()}))
        assert status == 0, (fmt, err)
    rng = random.Random(SEED)
    failures = _failures((n, _mesh_case(rng, tmp_path / f"case{n:03d}", bases)) for n in range(N_MESH_CASES))
    assert not failures, "\n".join(failures)
