"""Ctrl-C while VTK's extension modules load: deferred until they are in (geometries.mesh_files.vtk_family.load_vtk)."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

SCRIPT = """
import importlib, os, signal, sys
import geometries.mesh_files.vtk_family as mesh_io

real_import = importlib.import_module
def import_with_ctrl_c(name):
    if name == mesh_io.VTK_MODULES[1]:
        os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C half-way through the VTK imports
    return real_import(name)
mesh_io.importlib.import_module = import_with_ctrl_c
try:
    mesh_io.load_vtk()
except KeyboardInterrupt:
    print("interrupted after", sum(name in sys.modules for name in mesh_io.VTK_MODULES), "of", len(mesh_io.VTK_MODULES))
"""


def test_ctrl_c_during_the_vtk_imports_arrives_after_every_module_is_loaded():
    done = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, capture_output=True, text=True, timeout=120,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    n = len(__import__("geometries.mesh_files.vtk_family", fromlist=["VTK_MODULES"]).VTK_MODULES)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == f"interrupted after {n} of {n}"
