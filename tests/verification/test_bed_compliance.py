"""verification.bed_compliance: the bed's deflection under a reference's own contact pressure."""

from __future__ import annotations

import pytest

from edem.results import write_results
from edem.solver import solve
from geometries.errors import InputError
from tests.support import cylinder_patch, make_scene, plane
from verification.bed_compliance import BED_COMPLIANCE_METRICS, REGIONS, add_bed_compliance, bed_compliance
from verification.metrics import compare_result_dirs


def _cylinder_under_plane(**options):
    """M a cylinder patch (R 20 mm, springs along its radial normals, oblique away from the top)
    under a plane F touching it at rest through 2 mm of cartilage (gap law), 150 N along z, M free
    to move along y and z: the springs see its motion at their angles, linearised by the DEM's
    solve as by the check (d = t - h0 + g u)."""
    settings = {"law": "gap", "thickness_mm": 2.0, "coupling": "thin-layer", "poissons_ratio": 0.45, **options}
    return make_scene(cylinder_patch(20.0, 16.0, 40.0, 40, 32), plane(lambda x, y: 2.0), [[0.0, 0.0, 150.0]],
                      fixed_dofs=("tx", "rx", "ry", "rz"), method="dem", **settings)


@pytest.fixture(scope="module")
def own_run(tmp_path_factory):
    scene = _cylinder_under_plane()
    out = tmp_path_factory.mktemp("bed") / "dem"
    write_results(solve(scene, "dem"), out)
    return scene, out


def test_the_beds_own_contact_pressure_deflects_it_by_the_overlap_at_its_own_pose(own_run):
    scene, out = own_run
    (row,) = bed_compliance(scene, out)
    assert row["n_interior"] > 0 and row["n_edge"] > 0
    # On the active set the coupled solve's gap C f - (t - h) is zero to the round-off of its direct
    # factorisation; 1e-9 is far above that (about 1e-13 of the 0.1 mm overlaps) and far below any
    # bed error this check is for (percent).
    for region in REGIONS:
        assert row[f"ratio_{region}"] == pytest.approx(1.0, abs=1e-9), region


@pytest.mark.parametrize(("settings", "key"), [({"law": "threshold", "thickness_mm": None}, "cartilage.law"), ({"coupling": "none"}, "cartilage.coupling")])
def test_a_scene_without_an_overlap_for_a_layer_to_deflect_is_refused_naming_the_key(own_run, settings, key):
    _, out = own_run
    with pytest.raises(InputError) as refused:
        bed_compliance(_cylinder_under_plane(**settings), out, "the-scene.toml")
    assert refused.value.key == key and refused.value.file == "the-scene.toml"


def test_a_bed_of_another_modulus_deflects_in_inverse_proportion(own_run):
    # The compliance C is h/G times a function of nu and kh: E scaled by s scales it by 1/s exactly.
    _, out = own_run
    (row,) = bed_compliance(_cylinder_under_plane(youngs_modulus_mpa=1.25 * 10.35), out)
    for region in REGIONS:
        assert row[f"ratio_{region}"] == pytest.approx(1.0 / 1.25, rel=1e-9), region


def test_the_case_metrics_carry_each_time_points_ratio_into_the_comparison(own_run):
    scene, out = own_run
    comparison = compare_result_dirs(out, out)
    metrics = add_bed_compliance(comparison, bed_compliance(_cylinder_under_plane(youngs_modulus_mpa=2.0 * 10.35), out))
    (entry,) = comparison["per_time"]
    for name in BED_COMPLIANCE_METRICS:
        assert metrics[name] == entry[name] == pytest.approx(-0.5, rel=1e-9), name
