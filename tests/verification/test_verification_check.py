"""`edem check`, the regression gate (docs/campaigns.md#verdicts): EDEM rerun against the stored references of
verification/references/ (EDEM baselines and FE values). Drift against the stored baseline is the
gate (exit 1 with a table); the model error against the stored FE values is reported separately,
signed, judged on the regularised peak (summary.json's and the campaigns' definition), flagged
beyond the declared band, never a failure; 2 on bad input. Perturbations go to copies in tmp_path."""

from __future__ import annotations

import json
import shutil

import pytest

from edem.cli import main
from verification.check import (
    CHECK_SCENES,
    EDEM_TOLERANCES,
    FORMAT_VERSION,
    REFERENCES_DIR,
    coarse_field,
    field_difference,
    run_check,
)
from verification.campaign_model import THESIS_ANKLE


@pytest.fixture()
def references(tmp_path):
    target = tmp_path / "references"
    shutil.copytree(REFERENCES_DIR, target)
    return target


def _edit(path, change):
    data = json.loads(path.read_text(encoding="utf-8"))
    change(data)
    path.write_text(json.dumps(data), encoding="utf-8")


def test_stored_references_cover_the_declared_scenes():
    names = {check.name for check in CHECK_SCENES}
    assert {"ideal-standing", "subject-standing", "ideal-toe-off", "flat-plates"} == names
    for name in names:
        data = json.loads((REFERENCES_DIR / f"{name}.json").read_text(encoding="utf-8"))
        assert data["format"] == FORMAT_VERSION
        assert set(data["edem"]) >= {"regularised_peak_pressure_mpa", "peak_pressure_mpa", "contact_area_mm2", "displacement_mm", "pressure_field"}
        assert data["fe"] is not None or data["fe_unavailable"].startswith("FE reference not available")


def test_check_passes_on_the_stored_references(references, capsys):
    assert main(["check", "--references", str(references)]) == 0
    out = capsys.readouterr().out
    assert "edem check: ok: no drift" in out and "EDEM baseline" in out
    drift, model = out.split("Model error:")
    assert "Drift:" in drift and "FE slab" not in drift  # the two are reported apart


def test_check_fails_with_a_table_when_an_edem_baseline_drifted(references, capsys):
    key = "regularised_peak_pressure_mpa"
    tol = EDEM_TOLERANCES[key]
    _edit(references / "ideal-standing.json", lambda d: d["edem"][key].__setitem__(0, d["edem"][key][0] * (1 + 10 * tol)))
    assert main(["check", "--references", str(references)]) == 1
    out = capsys.readouterr().out
    drifted = out.split("drifted from the stored baseline:")[1]
    assert "1 of" in out and "ideal-standing" in drifted and key in drifted and "DRIFT" in drifted
    assert "subject-standing" not in drifted


def test_check_tolerates_perturbations_within_the_tolerance(references):
    tol = EDEM_TOLERANCES["contact_area_mm2"]
    _edit(references / "flat-plates.json", lambda d: d["edem"]["contact_area_mm2"].__setitem__(0, d["edem"]["contact_area_mm2"][0] * (1 + 0.5 * tol)))
    assert run_check(references=references) == 0


def test_model_error_beyond_the_band_is_flagged_not_failed(references, capsys):
    with_fe = [c.name for c in CHECK_SCENES if json.loads((references / f"{c.name}.json").read_text())["fe"]]
    if not with_fe:
        pytest.skip("the stored references hold no FE values (refreshed without the FE reference)")
    name = with_fe[0]
    # the FE area tripled: EDEM is far from it (a model error), but EDEM itself did not move
    _edit(references / f"{name}.json", lambda d: d["fe"]["contact_area_mm2"].__setitem__(0, d["fe"]["contact_area_mm2"][0] * 3.0))
    assert run_check(references=references) == 0
    out = capsys.readouterr().out
    model = out.split("Model error:")[1]
    row = next(line for line in model.splitlines() if line.startswith(name) and "contact_area_mm2" in line)
    assert row.rstrip().endswith("flagged") and "model errors flagged beyond the band" in out


def test_check_fails_when_the_field_drifted(references):
    def scale(d):
        field = d["edem"]["pressure_field"][0]
        field["pressure_mpa"] = [p * 1.01 for p in field["pressure_mpa"]]

    _edit(references / "subject-standing.json", scale)
    assert run_check(references=references) == 1


def test_missing_or_broken_reference_is_bad_input(references, capsys):
    (references / "ideal-toe-off.json").unlink()
    assert main(["check", "--references", str(references)]) == 2
    assert "no stored reference" in capsys.readouterr().err


def test_refresh_writes_references_that_then_pass(tmp_path):
    scenes = tuple(c for c in CHECK_SCENES if c.name == "flat-plates")
    assert run_check(refresh=True, references=tmp_path / "new", scenes=scenes, with_fe=False) == 0
    data = json.loads((tmp_path / "new" / "flat-plates.json").read_text())
    assert data["fe"] is None and "not requested" in data["fe_unavailable"]
    # p = F / A on the 20 x 20 mm plates, uniform: every spring's pressure and every 1 mm^2 disc's mean
    assert data["edem"]["peak_pressure_mpa"] == pytest.approx([400.0 / 400.0])
    assert data["edem"]["regularised_peak_pressure_mpa"] == pytest.approx([400.0 / 400.0])
    assert run_check(references=tmp_path / "new", scenes=scenes) == 0


def test_coarse_field_is_the_area_weighted_mean_per_cube():
    import numpy as np

    centroids = np.array([[0.5, 0.5, 0.5], [1.5, 0.5, 0.5], [2.5, 0.5, 0.5]])
    field = coarse_field(centroids, np.array([1.0, 3.0, 2.0]), np.array([4.0, 8.0, 1.0]), voxel_mm=2.0)
    assert field["cells"] == [[0, 0, 0], [1, 0, 0]]
    assert field["pressure_mpa"] == pytest.approx([(4 + 24) / 4, 1.0])
    other = {**field, "pressure_mpa": [7.0, 0.0]}
    assert field_difference(other, field) == pytest.approx(1.0 / np.sqrt(49 + 1))
    assert field_difference(field, field) == 0.0


def test_fe_null_without_a_reason_is_refused(references, capsys):
    """A reference whose FE values were removed ("fe": null, no stated reason) is bad input
    naming the file and the key, never a pass without the FE comparison."""

    def null_fe(d):
        d["fe"] = None
        d.pop("fe_unavailable", None)

    _edit(references / "flat-plates.json", null_fe)
    assert main(["check", "--references", str(references)]) == 2
    err = capsys.readouterr().err
    assert "flat-plates.json" in err and "key 'fe'" in err


@pytest.mark.parametrize("key,change", [
    ("edem.peak_pressure_mpa", lambda d: d["edem"]["peak_pressure_mpa"].__setitem__(0, None)),
    ("edem.regularised_peak_pressure_mpa", lambda d: d["edem"].pop("regularised_peak_pressure_mpa")),
    ("edem.displacement_mm", lambda d: d["edem"].pop("displacement_mm")),
    ("fe.pressure_field", lambda d: d["fe"].__setitem__("pressure_field", [])),
])
def test_incomplete_stored_quantities_are_refused(references, capsys, key, change):
    _edit(references / "flat-plates.json", change)
    assert main(["check", "--references", str(references)]) == 2
    err = capsys.readouterr().err
    assert "flat-plates.json" in err and f"key '{key}'" in err and "Traceback" not in err


def test_refresh_without_fe_keeps_the_stored_fe_values_and_says_so(references, capsys):
    scenes = tuple(c for c in CHECK_SCENES if c.name == "flat-plates")
    before = json.loads((references / "flat-plates.json").read_text())
    assert before["fe"] is not None
    assert run_check(refresh=True, references=references, scenes=scenes, with_fe=False) == 0
    after = json.loads((references / "flat-plates.json").read_text())
    assert after["fe"] == before["fe"] and after["fe_kept_from"] == before["refreshed_at"]
    assert "kept the stored FE values" in capsys.readouterr().out
    assert run_check(references=references, scenes=scenes) == 0


def test_refresh_without_fe_refuses_fe_values_of_other_time_points(references):
    from geometries.errors import InputError

    _edit(references / "flat-plates.json", lambda d: d["fe"].__setitem__("time_s", [0.5]))
    before = (references / "flat-plates.json").read_text()
    scenes = tuple(c for c in CHECK_SCENES if c.name == "flat-plates")
    with pytest.raises(InputError, match="other time points"):
        run_check(refresh=True, references=references, scenes=scenes, with_fe=False)
    assert (references / "flat-plates.json").read_text() == before


def _model_row(out: str, scene: str, quantity: str) -> str:
    model = out.split("Model error:")[1]
    return next(line for line in model.splitlines() if line.startswith(scene) and f" {quantity} " in line)


def test_old_format_reference_is_refused_by_name(references, capsys):
    """A format 1 reference (the raw peak only) is bad input naming the file, the key 'format' and
    the command that rewrites it, not compared on the wrong definition."""
    _edit(references / "ideal-standing.json", lambda d: d.__setitem__("format", 1))
    assert main(["check", "--references", str(references)]) == 2
    err = capsys.readouterr().err
    assert "ideal-standing.json" in err and "key 'format'" in err and f"format {FORMAT_VERSION}" in err
    assert "edem check --refresh" in err and "Traceback" not in err


def test_model_error_is_judged_on_the_regularised_peak_not_on_a_raw_rim_spike(references, capsys):
    """The FE's raw peak is a one-node rim spike 5x its regularised peak (as at the subject-like
    ankle's plafond pits): the judged pressure error is the regularised peaks' (EDEM - FE) / |FE|,
    unchanged; the raw peak's is reported, not judged (neither flagged nor counted)."""
    path = references / "ideal-standing.json"
    data = json.loads(path.read_text())
    reg_edem, reg_fe = data["edem"]["regularised_peak_pressure_mpa"][0], data["fe"]["regularised_peak_pressure_mpa"][0]
    _edit(path, lambda d: d["fe"]["peak_pressure_mpa"].__setitem__(0, 5.0 * reg_fe))
    assert run_check(references=references) == 0
    out = capsys.readouterr().out
    regularised = _model_row(out, "ideal-standing", "regularised_peak_pressure_mpa")
    assert f"{100 * (reg_edem - reg_fe) / reg_fe:+.1f} %" in regularised and regularised.rstrip().endswith("within band")
    raw = _model_row(out, "ideal-standing", "peak_pressure_mpa")
    raw_error = (data["edem"]["peak_pressure_mpa"][0] - 5.0 * reg_fe) / (5.0 * reg_fe)
    assert raw_error < -0.25 and f"{100 * raw_error:+.1f} %" in raw and raw.rstrip().endswith("reported, not judged")


@pytest.mark.parametrize("quantity,fe_factor,printed", [
    # (EDEM - FE) / |FE| with FE = 2 x EDEM: -50 %; FE = EDEM / 2: +100 %
    ("regularised_peak_pressure_mpa", 2.0, "-50.0 %"),
    ("contact_area_mm2", 0.5, "+100.0 %"),
    # |u - 2u| / |2u| = 50 %, negative: EDEM's bone moves less than the FE's
    ("displacement_mm", 2.0, "-50.0 %"),
])
def test_model_errors_are_printed_with_their_sign(references, capsys, quantity, fe_factor, printed):
    def scale(d):
        d["fe"][quantity] = [[fe_factor * x for x in v] if isinstance(v, list) else fe_factor * v for v in d["edem"][quantity]]

    _edit(references / "ideal-standing.json", scale)
    assert run_check(references=references) == 0  # a model error is flagged, never a failure
    row = _model_row(capsys.readouterr().out, "ideal-standing", quantity)
    assert printed in row and row.rstrip().endswith("flagged")


def test_stored_quantities_are_the_campaigns_definitions(tmp_path):
    """EDEM's and the FE's stored regularised peak are summary.json's (edem.pressure_metrics), the
    FE is measured on M (its summary's contact_area_on_mobile_mm2), and the model errors are the
    signed errors of `edem compare` / the campaigns (verification.metrics.compare_result_dirs)
    on the same two runs: one definition each. The ideal ankle's talus is curved, so its FE
    contact face is larger than M and the area on M differs from the face's (~13 % at 3 mm)."""
    from edem.resultdir import read_result_dir
    from verification.check import CheckScene, edem_quantities, fe_quantities, model_errors
    from verification.metrics import compare_result_dirs
    from verification.sides import OK, fe_availability, run_side
    from edem.results import write_results
    from edem.scene import load_scene
    from edem.solver import run

    if fe_availability() is not None:
        pytest.skip(fe_availability())
    check = CheckScene("ideal-standing", "ideal-standing", {**THESIS_ANKLE, "fe.mesh_size_mm": 3.0})  # the slab's twin; a coarse FE: ~8 s
    scene = load_scene(check.scene_ref(), dict(check.overrides))
    edem_dir = write_results(run(scene, "edem"), tmp_path / "edem")
    outcome = run_side("fe-slab", check.scene_ref(), dict(check.overrides), tmp_path / "fe")
    assert outcome.status == OK, outcome.message
    edem, fe = edem_quantities(edem_dir, scene), fe_quantities(outcome.result_dir, edem_dir, scene)
    # one time point: summary.json's regularised peak (the largest over the maps) is that point's
    assert edem["regularised_peak_pressure_mpa"] == [read_result_dir(edem_dir).summary["regularised_peak_pressure_mpa"]]
    fe_summary = read_result_dir(outcome.result_dir).summary
    assert fe["regularised_peak_pressure_mpa"] == [fe_summary["regularised_peak_pressure_mpa"]]
    assert fe["contact_area_mm2"] == fe_summary["contact_area_on_mobile_mm2"]
    face_area = float(read_result_dir(outcome.result_dir).timeseries["contact_area_mm2"][0])
    assert abs(face_area / fe["contact_area_mm2"][0] - 1.0) > 0.05  # the case tells the two surfaces apart
    errors, campaign = model_errors(edem, fe), compare_result_dirs(edem_dir, outcome.result_dir)["metrics"]
    for ours, theirs in (("regularised_peak_pressure_mpa", "regularised_peak_pressure_rel_error"), ("peak_pressure_mpa", "peak_pressure_rel_error"),
                         ("contact_area_mm2", "contact_area_rel_error"), ("displacement_mm", "displacement_rel_error")):
        assert errors[ours] == pytest.approx(campaign[theirs], rel=1e-12, abs=1e-15), ours  # the same arithmetic on the same numbers


def test_refresh_without_fe_does_not_keep_the_fe_values_of_an_old_format(references, capsys):
    """--no-fe keeps stored FE values only of the current format (format 1 has no regularised
    peak, and its FE was measured on its own face): it says why it kept none."""
    _edit(references / "flat-plates.json", lambda d: d.__setitem__("format", 1))
    scenes = tuple(c for c in CHECK_SCENES if c.name == "flat-plates")
    assert run_check(refresh=True, references=references, scenes=scenes, with_fe=False) == 0
    after = json.loads((references / "flat-plates.json").read_text())
    assert after["format"] == FORMAT_VERSION and after["fe"] is None and "not requested" in after["fe_unavailable"]
    out = capsys.readouterr().out
    assert "no stored FE values can be kept" in out and "key 'format'" in out
