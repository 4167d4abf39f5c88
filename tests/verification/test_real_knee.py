"""``real-knee`` (verification.campaigns.real_knee): the campaign on the public Lenhart knee.

Without the data it refuses, exit 2, naming ``--data`` (or the missing file), before anything is
written. Where the data exist (``../shared/data/lenhart2015-knee`` beside the repository, or
``EDEM_SHARED_DATA``), its prepared inputs give the FE layer on the measured tibial cartilage:
every tetrahedron upright, the contact face the articular surface itself, each column ending on
the subchondral bone where the bone lies below (the springs measure the same distance), and the
femoral articular surface 2 mm off its bone.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from edem.cli import main
from verification.campaigns import campaigns, get_campaign
from verification.campaigns.real_knee import DATA_FILES, FEMORAL_LAYER_MM

SHARED_DATA = Path(os.environ.get("EDEM_SHARED_DATA", Path(__file__).resolve().parents[2].parent / "shared" / "data"))
KNEE = SHARED_DATA / "lenhart2015-knee"


def test_real_knee_without_data_exits_2_naming_the_option_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["verify", "real-knee", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "'--data'" in err and "lenhart2015-R-tibia-cartilage.stl" in err and "Traceback" not in err
    assert not out.exists()


def test_real_knee_with_a_file_missing_exits_2_naming_the_file(tmp_path, capsys):
    folder = tmp_path / "knee"
    folder.mkdir()
    (folder / DATA_FILES["tibia_cartilage"]).write_text("solid empty\nendsolid empty\n")
    out = tmp_path / "out"
    assert main(["verify", "real-knee", "--data", str(folder), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert str(folder / DATA_FILES["tibia_bone"]) in err and "'--data'" in err and "Traceback" not in err
    assert not out.exists()


def test_data_is_refused_for_a_campaign_that_takes_none(tmp_path, capsys):
    assert main(["verify", "quick", "--data", str(tmp_path), "--out", str(tmp_path / "out")]) == 2
    assert "takes no data folder" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_real_knee_is_listed_with_its_expected_time(capsys):
    assert main(["verify", "--list"]) == 0
    line = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("real-knee"))
    assert "time not measured" not in line and "--data" in line
    assert campaigns()["real-knee"].expected_time_s > 0


@pytest.mark.skipif(not KNEE.is_dir(), reason=f"public knee data not found at {KNEE}")
def test_real_knee_fe_layer_stands_on_the_measured_bone(tmp_path):
    import warnings

    from edem.scene import load_scene
    from fem_reference.models import scene_layer_solid
    from fem_reference.problem import RigidSurface
    from geometries.fe_solids import CONTACT_TAG, tet_volumes
    from geometries.repair import prepare_surface

    campaign = get_campaign("real-knee", str(KNEE), tmp_path)
    scene = load_scene(campaign.cases[0].scene_ref())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the notes are checked by test_cartilage_solids
        solid = scene_layer_solid(scene, 1.0, 1)
    assert np.all(tet_volumes(solid.points_mm, solid.tets) > 0)
    nv = len(scene.mobile.vertices_mm)
    top = solid.points_mm[nv:]
    np.testing.assert_allclose(top, scene.mobile.vertices_mm, atol=1e-12)  # the contact face is the articular surface
    assert set(np.unique(solid.faces(CONTACT_TAG))) == set(range(nv, 2 * nv))
    # the columns measured to the bone end on it (1e-6 mm: the ray hits are re-measured in float64);
    # the others (rims beyond the bone mesh) take the springs' fallback
    bone = scene.cartilage.layers.mobile.bone
    gap, _ = RigidSurface(bone.vertices_mm, bone.triangles).gap_and_normal(solid.points_mm[:nv])
    on_bone = np.abs(gap) < 1e-6
    assert on_bone.mean() > 0.8, on_bone.mean()
    # the same cartilage as the springs': the thickness distributions agree (medians within 0.1 mm,
    # a vertex against a triangle centroid on 0.74 mm facets with the thickness varying 1-4 mm)
    column = np.linalg.norm(top - solid.points_mm[:nv], axis=1)
    assert abs(np.median(column) - np.median(scene.cartilage.layers.mobile.thickness_mm)) < 0.1
    # the femoral articular surface is its bone offset by the rigid 2 mm layer (the offset's vertex
    # normals lean from the facets': within 2 % of it near the tibia, where the contact is)
    femur = prepare_surface(KNEE / DATA_FILES["femur_bone"], units="m")
    gap, _ = RigidSurface(femur.vertices_mm, femur.triangles).gap_and_normal(scene.fixed.vertices_mm)
    assert np.median(np.abs(gap)) == pytest.approx(FEMORAL_LAYER_MM, rel=0.02)


def _row(a: float, b: float) -> dict:
    return {"status": "ran", "params": {}, "sides": [], "metrics": {"a_at_b_peak_pressure_mpa": a, "b_peak_pressure_mpa": b}}


@pytest.mark.parametrize("fe, discrete, verdict", [
    # FE 10 -> 10.2 (through the thickness), 10.3 (in the plane): f = 10.5, error 0.5 / 10.5 = 4.8 %
    ((10.0, 10.2, 10.3), 11.0, "within"),  # +4.8 %
    ((10.0, 10.2, 10.3), 13.0, "outside"),  # +23.8 %
    # an FE that moves 20 % under refinement judges nothing, however close the discrete value
    ((10.0, 12.0, 10.0), 12.0, "not judged"),
])
def test_fe_band_judges_only_where_the_fe_error_is_below_the_goal(fe, discrete, verdict):
    from verification.analyses import run_analysis
    from verification.campaign_model import Analysis

    rows = {f"c{k}": _row(discrete, value) for k, value in enumerate(fe)}
    analysis = Analysis("band", "t", "fe-band", tuple(rows), {
        "points": (("p", tuple(rows)),), "quantities": (("peak", "a_at_b_peak_pressure_mpa", "b_peak_pressure_mpa"),), "goal": 0.15})
    result = run_analysis(analysis, rows)
    entry = result["values"]["rows"][0]
    reference = fe[0] + sum(v - fe[0] for v in fe[1:])
    assert entry["fe_reference"] == pytest.approx(reference, rel=1e-15)
    assert entry["fe_error"] == pytest.approx(sum(abs(v - fe[0]) for v in fe[1:]) / reference, rel=1e-15)
    assert entry["difference"] == pytest.approx((discrete - reference) / reference, rel=1e-15)
    assert entry["verdict"].startswith(verdict)
    assert result["status"] == ("flagged" if verdict == "outside" else "reported")
