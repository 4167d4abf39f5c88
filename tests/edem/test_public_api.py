"""`import edem`: the public face (load_scene, Scene.from_arrays, solve, write_results, errors)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import edem
from support import grid_plate, plane

ROOT = Path(__file__).resolve().parents[2]
HEAVY = ("dolfinx", "pyvista", "vtk", "vtkmodules", "dask", "matplotlib", "opensim")


def test_importing_edem_loads_no_fe_plotting_or_vtk_library():
    """In a fresh interpreter (this one has imported the test suite's modules), after touching
    every public name (they load on first use)."""
    code = (f"import json, sys, edem; [getattr(edem, n) for n in edem.__all__]; "
            f"print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env={"PYTHONPATH": str(ROOT)}, capture_output=True, text=True, check=True)
    assert json.loads(out.stdout) == []


def test_public_names():
    assert {"load_scene", "Scene", "solve", "write_results", "InputError", "SolverError"} <= set(edem.__all__)
    assert issubclass(edem.InputError, ValueError)
    assert callable(edem.Scene.from_arrays)


def plates(force_n=(0.0, 0.0, 400.0), **kwargs) -> edem.Scene:
    """A 20 x 20 mm plate (32 springs) 2 mm below a plane, pressed up into it."""
    mobile, fixed = grid_plate(20, 20, 4), plane(lambda x, y: 2.0, size_mm=20.0)
    args = dict(youngs_modulus_mpa=10.35, poissons_ratio=0.42, fixed_dofs=("tx", "ty", "rx", "ry", "rz"))
    return edem.Scene.from_arrays(mobile.vertices_mm, mobile.triangles, fixed.vertices_mm, fixed.triangles, force_n, **{**args, **kwargs})


def test_scene_from_arrays_solves_the_flat_plates_closed_form(tmp_path):
    """Flat plates: p = F / A and d = p h / E' (linear springs: exact to round-off)."""
    result = edem.solve(plates(), method="dem")
    step = result.steps[0]
    e_conf = 10.35 * (1 - 0.42) / ((1 + 0.42) * (1 - 2 * 0.42))
    assert step.peak_pressure_mpa == pytest.approx(1.0, rel=1e-12)
    assert step.displacement_mm[2] == pytest.approx(2.0 / e_conf, rel=1e-12)
    out = edem.write_results(result, tmp_path / "plates")
    assert json.loads((out / "summary.json").read_text())["n_springs"] == 32


@pytest.mark.parametrize("change, key", [
    ({"law": "gap"}, "thickness_mm"),
    ({"law": "elastic"}, "law"),
    ({"fixed_dofs": ("tx", "yaw")}, "fixed_dofs"),
    ({"poissons_ratio": 0.5}, "poissons_ratio"),
])
def test_scene_from_arrays_refuses_bad_input_naming_the_argument(change, key):
    with pytest.raises(edem.InputError) as info:
        plates(**change)
    assert key in str(info.value) and isinstance(info.value, ValueError)


def test_bad_triangles_are_an_input_error():
    mobile = grid_plate(20, 20, 2)
    with pytest.raises(edem.InputError, match="mobile_triangles"):
        edem.Scene.from_arrays(mobile.vertices_mm, mobile.triangles + 100, mobile.vertices_mm, mobile.triangles, [0, 0, 1.0],
                               youngs_modulus_mpa=1.0, poissons_ratio=0.3)


def test_solve_refuses_a_load_pulling_the_plates_apart_and_an_unknown_method():
    with pytest.raises(edem.SolverError, match="no equilibrium"):
        edem.solve(plates(force_n=(0.0, 0.0, -100.0)), method="dem")
    with pytest.raises(edem.InputError, match="method"):
        edem.solve(plates(), method="fem")
