"""Scene checks a new user meets first: warnings that survive a refused run, a unit mismatch
refused, a gap-law bed that starts compressed warned."""

from __future__ import annotations

import numpy as np
import pytest
from support import grid_plate, make_scene, plane

from edem.cli import main
from edem.solver import run
from geometries.mesh_files import write_surface
from geometries.surface import TriangleSurface

SCENE = """[geometry]
mobile = "talus.stl"
fixed = "tibia.stl"
{units}
[cartilage]
youngs_modulus_mpa = 10.35
poissons_ratio = 0.42
[load]
force_n = [0.0, 0.0, {force}]
[constraints]
fixed_dofs = ["tx", "ty", "rz"]
"""


def write_plates(tmp_path, talus: TriangleSurface, tibia: TriangleSurface, force: float, units: str = ""):
    write_surface(tmp_path / "talus.stl", talus)
    write_surface(tmp_path / "tibia.stl", tibia)
    path = tmp_path / "s.toml"
    path.write_text(SCENE.format(units=units, force=force), encoding="utf-8")
    return path


def test_scene_warnings_are_printed_even_when_the_run_is_refused(tmp_path, capsys):
    """A talus mesh with 3 triangles wound against their neighbours (repaired, warned at load)
    under a load pulling the plates apart (refused): exit 2 and the repair warning is on stderr."""
    talus = grid_plate(20, 20, 10)
    triangles = talus.triangles.copy()
    triangles[:3] = triangles[:3, ::-1]
    scene = write_plates(tmp_path, TriangleSurface(talus.vertices_mm, triangles), plane(lambda x, y: 2.0, 30.0), -100.0)
    assert main(["run", str(scene), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "3 triangles were oriented against their neighbours" in err and "no solution" in err


def test_meshes_in_metres_without_units_are_refused(tmp_path, capsys):
    """Plates 20 mm wide written in metres (0.02 across) and no units = "m": exit 2 naming the
    key and the fix, instead of a solve on a 0.03 mm joint. With units = "m" it runs."""
    talus, tibia = grid_plate(20, 20, 10), plane(lambda x, y: 2.0, 30.0)
    in_metres = [TriangleSurface(s.vertices_mm / 1000.0, s.triangles) for s in (talus, tibia)]
    scene = write_plates(tmp_path, *in_metres, 400.0)
    assert main(["run", str(scene), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "geometry.mobile" in err and 'units = "m"' in err and "looks like it is in metres" in err
    scene = write_plates(tmp_path, *in_metres, 400.0, units='units = "m"')
    assert main(["run", str(scene), "--out", str(tmp_path / "out")]) == 0


@pytest.mark.parametrize("law", ["gap", "gap-log"])
def test_gap_bed_that_starts_compressed_is_warned(law):
    """Plates 1.2 mm apart with t = 2 mm: every spring starts 0.8 mm compressed; warned with the
    amount. 2.5 mm apart: not; 1.99 mm apart (0.5 % of t, under TOUCHING_OVERLAP = 1 %): touching,
    not warned; 1.97 mm (1.5 %): warned."""
    compressed = run(make_scene(grid_plate(20, 20, 8), plane(lambda x, y: 1.2), [0, 0, 100.0], law=law, thickness_mm=2.0,
                                max_spring_length_mm=4.0, fixed_dofs=("tx", "ty", "rx", "ry", "rz")), "dem")
    assert any("pre-compressed" in w and "128 springs" in w and "by up to 0.8 mm" in w for w in compressed.warnings)
    apart = run(make_scene(grid_plate(20, 20, 8), plane(lambda x, y: 2.5), [0, 0, 100.0], law=law, thickness_mm=2.0,
                           max_spring_length_mm=4.0, fixed_dofs=("tx", "ty", "rx", "ry", "rz")), "dem")
    assert not any("pre-compressed" in w for w in apart.warnings)
    assert np.isfinite(apart.steps[0].displacement_mm).all()
    for gap, warned in ((1.99, False), (1.97, True)):
        touching = run(make_scene(grid_plate(20, 20, 8), plane(lambda x, y: gap), [0, 0, 100.0], law=law, thickness_mm=2.0,
                                  max_spring_length_mm=4.0, fixed_dofs=("tx", "ty", "rx", "ry", "rz")), "dem")
        assert any("pre-compressed" in w for w in touching.warnings) == warned, gap
