"""Dependencies by need (pyproject.toml's extras, geometries/extras.py): the solver and its scenes
run on the core install; a missing extra is exit 2 naming the extra, not an ImportError traceback.

The core install is simulated by blocking the extras' modules (``sys.modules[name] = None`` makes
their import fail as if they were not installed) in a fresh interpreter.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from support import grid_plate, plane

from geometries.builders import build_geometry, clear_geometry_cache
from geometries.extras import EXTRA_OF_MODULE, MissingExtra
from geometries.mesh_files import read_surface, write_surface

ROOT = Path(__file__).resolve().parents[2]
BLOCK_EXTRAS = f"import sys; sys.modules.update(dict.fromkeys({sorted(EXTRA_OF_MODULE)!r}));"


def run_python(code: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(ROOT / "tests")])}
    return subprocess.run([sys.executable, "-c", BLOCK_EXTRAS + code], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=600)


def test_a_curved_builtin_without_gmsh_names_the_gmsh_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "gmsh", None)
    clear_geometry_cache()
    with pytest.raises(MissingExtra, match=r"'gmsh'.*pip install 'edem\[gmsh\]'") as err:
        build_geometry("ideal_ankle", {"mesh_size_mm": 5.0})
    assert err.value.extra == "gmsh"


def test_a_vtk_file_without_vtk_names_the_vtk_extra(monkeypatch, tmp_path):
    path = tmp_path / "plate.vtp"
    write_surface(path, grid_plate(4, 4, 2))  # written without VTK
    monkeypatch.setitem(sys.modules, "vtkmodules", None)
    for name in [m for m in sys.modules if m.startswith("vtkmodules.")]:
        monkeypatch.delitem(sys.modules, name)
    with pytest.raises(MissingExtra, match=r"reading VTK files needs .*'vtk'.*pip install 'edem\[vtk\]'"):
        read_surface(path)


def test_edem_run_of_mesh_files_and_of_numpy_built_scenes_needs_no_extra(tmp_path):
    """STL meshes and the plate, tilted-plane and hemisphere builders run on the core install and
    write their whole result directory (pressure maps included); nothing optional is imported."""
    write_surface(tmp_path / "talus.stl", grid_plate(20, 20, 10))
    write_surface(tmp_path / "tibia.stl", plane(lambda x, y: 2.0, size_mm=30.0))
    (tmp_path / "plates.toml").write_text(
        '[scene]\nname = "plates"\n[geometry]\nmobile = "talus.stl"\nfixed = "tibia.stl"\n'
        "[cartilage]\nyoungs_modulus_mpa = 10.35\npoissons_ratio = 0.42\n"
        '[load]\nforce_n = [0.0, 0.0, 400.0]\n[constraints]\nfixed_dofs = ["tx", "ty", "rz"]\n', encoding="utf-8")
    scenes = [str(tmp_path / "plates.toml"), str(ROOT / "verification/scenes/tilted-plane.toml"), "hemisphere-convergence"]
    code = ("from edem.cli import main\n"
            f"for k, scene in enumerate({scenes!r}):\n"
            "    assert main(['run', scene, '--out', f'out{k}']) == 0, scene\n"
            "loaded = sorted({m.split('.')[0] for m in sys.modules if m.split('.')[0] in " + repr(sorted(EXTRA_OF_MODULE)) + " and sys.modules[m]})\n"
            "assert not loaded, loaded\n")
    done = run_python(code, tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    for k in range(len(scenes)):
        assert (tmp_path / f"out{k}" / "pressure_0000.vtp").is_file()


def test_a_command_that_needs_an_extra_is_exit_2_naming_it(tmp_path):
    """edem plot needs matplotlib (render), a curved built-in scene needs gmsh: exit 2 and the
    pip command, no traceback."""
    plates = str(ROOT / "verification/scenes/flat-plates.toml")
    for code, extra in ((f"from edem.cli import main; assert main(['run', {plates!r}, '--out', 'out']) == 0; "
                         "sys.exit(main(['plot', 'out']))", "render"),
                        ("from edem.cli import main; sys.exit(main(['run', 'ideal-standing']))", "gmsh")):
        done = run_python(code, tmp_path)
        assert done.returncode == 2, done.stderr[-3000:]
        assert f"pip install 'edem[{extra}]'" in done.stderr and "Traceback" not in done.stderr, done.stderr[-3000:]
