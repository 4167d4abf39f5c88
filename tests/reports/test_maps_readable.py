"""Pressure maps and renders a clinician can read: exact agreement is white on the difference
panel, ankles are drawn in anatomical orientation, and off-screen renders print no X-server
notice."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pyvista")

ROOT = Path(__file__).resolve().parents[2]


def _result_dir(scene_name: str, out: Path, method: str = "dem") -> Path:
    from edem.results import write_results
    from edem.scene import load_scene
    from edem.solver import run

    return write_results(run(load_scene(scene_name), method), out)


def test_identical_runs_give_a_white_difference_panel(tmp_path):
    # Two identical DEM runs differ by exactly 0 everywhere; an unlit "bwr" panel draws 0 as
    # pure white (255, 255, 255). A lit surface would shade it grey: the bug this guards.
    from matplotlib.image import imread

    from reports.maps import render_pressure_maps

    plates = str(ROOT / "verification" / "scenes" / "flat-plates.toml")
    a, b = _result_dir(plates, tmp_path / "a"), _result_dir(plates, tmp_path / "b")
    png = render_pressure_maps(a, b, tmp_path / "maps.png", window_size=(900, 400))
    image = imread(png)[..., :3]
    height, width = image.shape[:2]
    # the middle of the third panel lies on the plate (the view frames the surface)
    centre = image[height // 2 - 5 : height // 2 + 5, 5 * width // 6 - 5 : 5 * width // 6 + 5]
    assert np.all(centre >= 0.99)


def test_ankle_result_dirs_are_recognised_as_anatomical(tmp_path):
    from reports.maps import is_anatomical

    plates = str(ROOT / "verification" / "scenes" / "flat-plates.toml")
    assert is_anatomical(_result_dir("ideal-standing", tmp_path / "ankle"))
    assert not is_anatomical(_result_dir(plates, tmp_path / "plates"))


def test_offscreen_render_prints_no_x_server_notice(tmp_path):
    # Without DISPLAY, VTK logs "bad X server connection" before falling back to an off-screen
    # context: harmless, and it must not reach the user's terminal.
    code = (
        "from geometries.builders import build_geometry; from geometries.render import render_geometry_png; "
        f"render_geometry_png(build_geometry('flat_plates', {{}}), {str(tmp_path / 'plates.png')!r})"
    )
    env = {k: v for k, v in os.environ.items() if k != "DISPLAY"}
    env["PYTHONPATH"] = str(ROOT)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "plates.png").is_file()
    assert "X server" not in done.stderr and "WARN" not in done.stderr
