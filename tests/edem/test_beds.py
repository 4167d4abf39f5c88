"""The bed registry (edem.beds.BEDS): every bed balances the load, the scene picks the bed by
``[cartilage] coupling`` from a file or from arrays, one validator refuses the same cartilage both
ways, and the run solves with whatever bed the registry holds."""

from __future__ import annotations

import json
from dataclasses import dataclass, replace

import numpy as np
import pytest
from support import grid_plate, plane

from edem.beds import BEDS, CoupledThinLayer, IndependentSprings, scene_bed
from edem.cli import main
from geometries.errors import InputError
from edem.mechanics import generalised_directions
from edem.raycast import RayCaster
from edem.scene import Scene, load_scene
from edem.solver import run
from edem.layer_symbols import LAYER_SYMBOLS

#: every bed of the registry with each of its symbols (coupling, thin_layer_symbol)
BED_CHOICES = [(IndependentSprings.coupling, None)] + [(CoupledThinLayer.coupling, symbol) for symbol in LAYER_SYMBOLS]
THICKNESS_MM, FORCE_N = 2.0, 333.0
PLATE_MM2 = 400.0  # 20 x 20 mm


def plates(coupling: str = IndependentSprings.coupling, thin_layer_symbol: str | None = None, **kwargs) -> Scene:
    """A 20 x 20 mm plate (512 springs) 2 mm below a plane, pressed up into it, then also tilted
    by a moment about x and y (G: the plate's centre)."""
    mobile, fixed = grid_plate(20, 20, 16), plane(lambda x, y: THICKNESS_MM)
    force = [[0.0, 0.0, FORCE_N], [0.0, 0.0, FORCE_N]]
    moment = [[0.0, 0.0, 0.0], [300.0, -200.0, 0.0]]
    args = dict(youngs_modulus_mpa=10.35, poissons_ratio=0.45, law="gap", thickness_mm=THICKNESS_MM, max_spring_length_mm=2 * THICKNESS_MM,
                fixed_dofs=("tx", "ty", "rz"), moment_nmm=moment, coupling=coupling, thin_layer_symbol=thin_layer_symbol)
    return Scene.from_arrays(mobile.vertices_mm, mobile.triangles, fixed.vertices_mm, fixed.triangles, force, **{**args, **kwargs})


def test_the_choices_cover_the_registry():
    """A bed added to BEDS without a line in BED_CHOICES would escape the tests below."""
    assert {coupling for coupling, _ in BED_CHOICES} == set(BEDS)


@pytest.mark.parametrize("coupling, symbol", BED_CHOICES)
def test_every_bed_balances_force_and_moment_on_flat_plates(coupling, symbol):
    """Force and moment balance of the output pressures, sum p A g = T on the free DOFs, and
    under the centred force alone (every spring in contact) the mean pressure F / A.
    Tolerance 1e-9 of the load: the solves balance to round-off (their own residual checks are
    1e-6 relative and looser); the pressures differ between the beds by tens of percent at nu 0.45."""
    scene = plates(coupling, symbol)
    assert scene.cartilage.coupling == coupling
    assert scene.cartilage.bed_keys == BEDS[coupling].Keys(**({} if symbol is None else {"thin_layer_symbol": symbol}))
    result = run(scene, "dem")
    rows = generalised_directions(scene.spring_centroid_mm, scene.spring_normal, scene.reference_point_mm)
    free = [2, 3, 4]  # tz, rx, ry (tx, ty, rz fixed)
    for step in result.steps:
        load = np.concatenate([step.force_n, step.moment_nmm])
        resultant = rows.T @ (step.pressure_mpa * step.area_mm2)
        np.testing.assert_allclose(resultant[free], load[free], rtol=0, atol=1e-9 * FORCE_N * 10.0)  # moments: arm ~10 mm
    centred = result.steps[0]
    assert centred.in_contact.all()
    assert centred.mean_pressure_mpa == pytest.approx(FORCE_N / PLATE_MM2, rel=1e-9)


def test_the_scene_from_arrays_picks_the_bed_the_run_solves_with():
    """At nu 0.45 the coupled layer redistributes the pressure under flat plates (edge effects)
    while the independent springs stay uniform at p = F / A: the choice reaches the solve."""
    springs = run(plates(), "dem").steps[0]
    layer = run(plates("thin-layer", "pade"), "dem").steps[0]
    np.testing.assert_allclose(springs.pressure_mpa, FORCE_N / PLATE_MM2, rtol=1e-12)  # round-off of 512 equal springs
    assert np.ptp(layer.pressure_mpa) > 0.1 * FORCE_N / PLATE_MM2


def test_an_unknown_bed_is_refused_naming_the_key():
    with pytest.raises(InputError) as from_file:
        load_scene("cylinder-layer", {"cartilage.coupling": "springs"})
    assert from_file.value.key == "cartilage.coupling" and all(name in from_file.value.expected for name in BEDS)
    with pytest.raises(InputError) as from_arrays:
        plates("springs")
    assert from_arrays.value.key == "coupling"
    scene = load_scene("cylinder-layer")
    bypassed = replace(scene, cartilage=replace(scene.cartilage, coupling="springs"))  # past the validator
    with pytest.raises(InputError) as at_run:
        run(bypassed)
    assert at_run.value.key == "cartilage.coupling"


@pytest.mark.parametrize("change, key", [
    ({"max_spring_length_mm": 1.5}, "max_spring_length_mm"),  # h_max below the thickness
    ({"thin_layer_symbol": "two-pole"}, "thin_layer_symbol"),  # a symbol without the coupling
    ({"coupling": "thin-layer", "thin_layer_symbol": "pade-2"}, "thin_layer_symbol"),
    ({"coupling": "thin-layer", "law": "gap-log", "thin_layer_symbol": "two-pole"}, "thin_layer_symbol"),  # columns not linearisable
    ({"thin_layer_smoothing_resolution": 3.0}, "thin_layer_smoothing_resolution"),  # a coarse smoothing without the coupling
    ({"coupling": "thin-layer", "thin_layer_smoothing_resolution": -1.0}, "thin_layer_smoothing_resolution"),
    ({"thin_layer_stack": "lumped"}, "thin_layer_stack"),  # how two layers couple, without the coupling
    ({"coupling": "thin-layer", "thin_layer_stack": "bonded"}, "thin_layer_stack"),
    ({"shear_modulus_mpa": -1.0}, "shear_modulus_mpa"),
    ({"law": "elastic"}, "law"),
])
def test_the_file_and_the_arrays_refuse_the_same_cartilage(change, key):
    """One validator: the same problem and expectation, keyed `cartilage.<key>` in a scene file
    and `<key>` (the argument) in Scene.from_arrays."""
    with pytest.raises(InputError) as from_file:
        load_scene("cylinder-layer", {f"cartilage.{k}": v for k, v in change.items()})
    with pytest.raises(InputError) as from_arrays:
        plates(**{"poissons_ratio": 0.42, **change})  # the file's cartilage (law gap, t 2 mm, h_max 4 mm, nu 0.42)
    assert (from_file.value.key, from_arrays.value.key) == (f"cartilage.{key}", key)
    assert (from_file.value.problem, from_file.value.expected) == (from_arrays.value.problem, from_arrays.value.expected)


def test_the_run_solves_with_the_bed_the_registry_holds(monkeypatch):
    """A bed registered under a new key is what the run solves with (the run does not name the
    beds): one solve per time point, the first-step warnings once, and here (the independent
    springs' numbers) the same result to the bit."""
    calls = {"solve": 0, "first": 0}

    class Counted(IndependentSprings):
        coupling = "counted"

        def solve(self, step, load):
            calls["solve"] += 1
            return super().solve(step, load)

        def first_step_warnings(self, step, solution):
            calls["first"] += 1
            return super().first_step_warnings(step, solution)

    monkeypatch.setitem(BEDS, Counted.coupling, Counted)
    springs = plates()
    counted = replace(springs, cartilage=replace(springs.cartilage, coupling="counted"))
    assert isinstance(scene_bed(counted, RayCaster(counted.fixed.vertices_mm, counted.fixed.triangles)), Counted)
    expected, got = run(springs, "edem"), run(counted, "edem")
    assert calls == {"solve": len(springs.load.time_s), "first": 1}
    for a, b in zip(expected.steps, got.steps):
        np.testing.assert_array_equal(a.pressure_mpa, b.pressure_mpa)
        np.testing.assert_array_equal(a.displacement_mm, b.displacement_mm)


def test_a_bed_with_keys_of_its_own_is_read_refused_and_summarised_from_the_registry_alone(monkeypatch, tmp_path, capsys):
    """A bed added to BEDS with a key of its own and nothing else changed: a scene file (through
    ``--set``) and Scene.from_arrays take its key, the validator refuses a bad value and the key
    on another bed (naming it and the bed it belongs to), summary.json lists it (null on another
    bed, whose own keys are null on this one) and the one-line report gives the bed's label."""

    @dataclass(frozen=True)
    class StiffenedKeys:
        stiffness_factor: float = 1.0

    class Stiffened(IndependentSprings):
        coupling, label, Keys = "stiffened", "stiffened springs", StiffenedKeys

        @classmethod
        def read_keys(cls, table):
            return cls.Keys(table.number("stiffness_factor", 1.0, positive=True, what="a factor > 0"))

    monkeypatch.setitem(BEDS, Stiffened.coupling, Stiffened)
    assert plates(Stiffened.coupling, stiffness_factor=2.0).cartilage.bed_keys == StiffenedKeys(2.0)
    for change, key, expected in (({"cartilage.stiffness_factor": 2.0}, "cartilage.stiffness_factor", 'coupling = "stiffened"'),
                                  ({"cartilage.coupling": "stiffened", "cartilage.stiffness_factor": -1.0}, "cartilage.stiffness_factor", "> 0"),
                                  ({"cartilage.coupling": "stiffened", "cartilage.thin_layer_symbol": "pade"}, "cartilage.thin_layer_symbol",
                                   'coupling = "thin-layer"')):
        with pytest.raises(InputError) as refused:
            load_scene("cylinder-layer", change)
        assert refused.value.key == key and expected in refused.value.expected
    summaries = {}
    for coupling, extra in ((Stiffened.coupling, ["--set", "cartilage.stiffness_factor=2"]), (CoupledThinLayer.coupling, [])):
        out = tmp_path / coupling
        assert main(["run", "cylinder-layer", "--method", "dem", "--out", str(out), "--set", f"cartilage.coupling={coupling}", *extra]) == 0
        summaries[coupling] = json.loads((out / "summary.json").read_text())
        assert BEDS[coupling].label in capsys.readouterr().out
    assert {k: summaries["stiffened"][k] for k in ("coupling", "stiffness_factor", "thin_layer_symbol")} == {
        "coupling": "stiffened", "stiffness_factor": 2.0, "thin_layer_symbol": None}
    assert (summaries["thin-layer"]["stiffness_factor"], summaries["thin-layer"]["thin_layer_symbol"]) == (None, "pade")
