"""The worked examples of docs/examples/ run as written and give the numbers their docstrings
state (so the documentation cannot drift from what the code computes). Each example's own
constants hold its expected numbers and tolerances (the origin of each is stated beside them in
the example's docstring); these tests check that the docstring quotes those constants and that a
run meets them. The examples on public data run where the data folder exists (EDEM_SHARED_DATA,
or ../shared/data beside the repository, where CI has it), and are skipped otherwise."""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "docs" / "examples"
DATA = Path(os.environ.get("EDEM_SHARED_DATA", ROOT.parent / "shared" / "data"))


def example(name: str):
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_paraboloid_matches_the_elastic_foundation_closed_form_and_the_coupled_layer_converges_to_it(tmp_path):
    pytest.importorskip("matplotlib")
    ex = example("paraboloid_from_arrays")
    closed = ex.winkler(ex.LOADS_N, ex.THICKNESSES_MM[0])
    doc = " ".join(ex.__doc__.split())
    for key, fmt in (("approach_mm", "{:.3f}"), ("radius_mm", "{:.2f}"), ("peak_mpa", "{:.2f}")):
        assert " / ".join(fmt.format(x) for x in closed[key]) in doc, key
    numbers = ex.main(["--out", str(tmp_path)])
    assert (tmp_path / "pressure.png").stat().st_size > 0
    for t in ex.THICKNESSES_MM:
        springs = numbers[f"t={t:g}/none"]
        for key, name in (("approach_mm_ratio", "approach"), ("peak_mpa_ratio", "peak"), ("area_mm2_ratio", "area")):
            np.testing.assert_allclose(springs[key], 1.0, atol=ex.TOLERANCE[name], err_msg=f"t = {t}: {key}")
        for coupling in ("none", "thin-layer"):
            case = numbers[f"t={t:g}/{coupling}"]
            # force balance: the pressures sum to the load (the solver balances to 1e-10 of it)
            np.testing.assert_allclose(case["pressure_sum_n"], ex.LOADS_N, rtol=1e-9)
    thick, thin = (np.abs(np.array(numbers[f"t={t:g}/thin-layer"]["approach_mm_ratio"]) - 1.0) for t in ex.THICKNESSES_MM)
    # the coupled layer's departure from the foundation shrinks with t/a (ratio 0.35 here; 0.6 leaves
    # room for the 0.1-0.2 % discretisation error the independent springs show at the same mesh)
    assert np.all(thin < 0.6 * thick), (thin, thick)


KNEE = DATA / "lenhart2015-knee"


@pytest.mark.skipif(not KNEE.is_dir(), reason=f"public knee data not at {KNEE}")
def test_knee_area_grows_with_load_does_not_depend_on_h_max_and_is_as_documented(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    ex = example("lenhart_knee")
    doc = " ".join(ex.__doc__.split())
    for bed, areas in ex.EXPECTED_AREA_MM2.items():
        assert " / ".join(f"{a:.0f}" for a in areas) in doc, bed
    # as docs/examples/README.md runs it: from the repository, with paths relative to it
    monkeypatch.chdir(ROOT)
    numbers = ex.main(["--data", os.path.relpath(DATA, ROOT), "--out", os.path.relpath(tmp_path, ROOT)])
    assert (tmp_path / "pressure.png").stat().st_size > 0
    half_spring = 0.5 * numbers["largest_spring_mm2"]
    for bed, expected in ex.EXPECTED_AREA_MM2.items():
        area = {h: np.array(numbers[f"{bed}/h_max={h:g}"]["area_mm2"]) for h in ex.WINDOWS_MM}
        first, second = (area[h] for h in ex.WINDOWS_MM)
        np.testing.assert_allclose(first, expected, rtol=ex.AREA_RTOL, err_msg=bed)
        assert np.all(np.diff(first) > 0), first
        # h_max only decides which far surfaces the rays see: nothing in contact may change
        np.testing.assert_allclose(second, first, rtol=0.0, atol=half_spring, err_msg=bed)


GAIT = DATA / "opensim-gait2392"


@pytest.mark.opensim
@pytest.mark.skipif(not GAIT.is_dir(), reason=f"public OpenSim data not at {GAIT}")
def test_gait_reaction_keeps_the_ankle_in_contact_and_the_contact_balances_minus_the_reaction(tmp_path):
    pytest.importorskip("opensim")
    pytest.importorskip("matplotlib")
    ex = example("gait2392_ankle")
    doc = " ".join(ex.__doc__.split())
    assert f"about {ex.EXPECTED_PEAK_REACTION_N / 1000:g} kN" in doc
    assert f"talar layer of {ex.TALAR_CARTILAGE_MM} mm and a tibial layer of {ex.TIBIAL_CARTILAGE_MM} mm" in doc
    numbers = ex.main(["--data", str(DATA), "--out", str(tmp_path)])
    assert (tmp_path / "stance.png").stat().st_size > 0
    assert numbers["times_match"] and numbers["rows"] == 48  # the stance's 48 rows of the .sto, one run step each
    # "about 4 kN" is quoted to one significant figure (3.5-4.5 kN round to it: 12.5 %), hence 15 %;
    # what it guards against (another joint, body or unit, or the muscle forces left out) moves the
    # peak by a factor of 2 or more
    assert abs(numbers["peak_reaction_n"] - ex.EXPECTED_PEAK_REACTION_N) < 0.15 * ex.EXPECTED_PEAK_REACTION_N
    assert numbers["loaded_rows"] >= 30 and numbers["loaded_rows_in_contact"] == numbers["loaded_rows"]
    # the contact and the constraints alone carry the load; EDEM balances each step to 1e-10 of it
    assert numbers["max_balance_error_n"] < 1e-6 * numbers["peak_reaction_n"]
