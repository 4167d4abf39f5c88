"""VTK files are read in a forked child process: a crash of VTK's C++ readers ends the child and
is an InputError naming the file (geometries/mesh_files/child.py, docs/method.md#8-built-in-geometries)."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import warnings
from pathlib import Path

import pytest
from support import grid_plate, plane

from geometries.errors import InputError, MeshWarning
from geometries.mesh_files import read_surface, vtk_family, write_surface
from geometries.mesh_files.child import run_in_child

ROOT = Path(__file__).resolve().parents[2]


def _segfault() -> None:
    os.kill(os.getpid(), signal.SIGSEGV)


def _warn_then_refuse(text: str) -> None:
    warnings.warn(text, MeshWarning)
    raise InputError("refused in the child", file="f.vtk", key="geometry.fixed", expected="something else")


def _bug() -> None:
    raise ZeroDivisionError("a bug, not the file")


def _vtk_xml_that_aborts_vtk(tmp_path: Path, name: str) -> Path:
    """A .vtu whose NumberOfComponents is -3: VTK's XML reader resizes to it unchecked and the
    process aborts (std::length_error, SIGABRT; a mesh fuzz found it). The header check refuses
    it before VTK reads, so the tests below call VTK's read without that check."""
    whole = tmp_path / "whole.vtu"
    write_surface(whole, grid_plate(4, 4, 10))
    text = whole.read_bytes()
    found = re.search(rb'NumberOfComponents="[^"]*"', text)
    bad = tmp_path / name
    bad.write_bytes(text[: found.start()] + b'NumberOfComponents="-3"' + text[found.end():])
    return bad


def test_a_segfault_in_the_child_is_an_input_error_naming_the_file_and_key():
    with pytest.raises(InputError, match="SIGSEGV") as err:
        run_in_child(_segfault, file="bones/talus.vtp", key="geometry.mobile", expected="a valid mesh file")
    assert err.value.file == "bones/talus.vtp" and err.value.key == "geometry.mobile"


def test_the_child_s_result_input_error_and_warnings_reach_the_parent():
    assert run_in_child(sorted, [3, 1, 2], file="x", key=None, expected="y") == [1, 2, 3]
    with pytest.warns(MeshWarning, match="dropped in the child"), pytest.raises(InputError) as err:
        run_in_child(_warn_then_refuse, "2 cells dropped in the child", file="x", key=None, expected="y")
    assert (err.value.problem, err.value.file, err.value.key, err.value.expected) == (
        "refused in the child", "f.vtk", "geometry.fixed", "something else")


def test_a_bug_in_the_child_is_not_blamed_on_the_file():
    with pytest.raises(RuntimeError, match="ZeroDivisionError: a bug, not the file"):
        run_in_child(_bug, file="x", key=None, expected="y")


def test_a_file_that_aborts_vtk_ends_the_child_not_this_process(tmp_path):
    pytest.importorskip("vtk")
    bad = _vtk_xml_that_aborts_vtk(tmp_path, "talus.vtu")
    with pytest.raises(InputError, match="crashed on this file .*SIGABRT") as err:
        run_in_child(vtk_family._read_with_vtk, bad, "geometry.mobile", file=str(bad), key="geometry.mobile", expected="a mesh")
    assert str(bad) in str(err.value) and "geometry.mobile" in str(err.value)
    assert read_surface(tmp_path / "whole.vtu").n_triangles == 2 * 10 * 10  # this process reads on


def test_a_reader_crash_during_edem_run_is_exit_2_naming_the_file(tmp_path):
    """End to end, with the header check that would refuse the file first switched off: the
    run ends with exit status 2 and a message naming the file and key, no traceback."""
    pytest.importorskip("vtk")
    bad = _vtk_xml_that_aborts_vtk(tmp_path, "talus.vtu")
    write_surface(tmp_path / "tibia.stl", plane(lambda x, y: 2.0, size_mm=30.0))
    scene = tmp_path / "scene.toml"
    scene.write_text('[scene]\nname = "crash"\n[geometry]\nmobile = "talus.vtu"\nfixed = "tibia.stl"\n'
                     "[cartilage]\nyoungs_modulus_mpa = 10.35\npoissons_ratio = 0.42\n"
                     "[load]\nforce_n = [0.0, 0.0, 400.0]\n", encoding="utf-8")
    code = ("import sys; import geometries.mesh_files.vtk_family as v; v._check_header = lambda path, key: None; "
            f"from edem.cli import main; sys.exit(main(['run', {str(scene)!r}, '--out', {str(tmp_path / 'out')!r}]))")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(ROOT / "tests")])})
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    assert str(bad) in done.stderr and "geometry.mobile" in done.stderr and "SIGABRT" in done.stderr
