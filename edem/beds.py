"""Spring beds: what carries the contact between the bones, one class per bed, registered in :data:`BEDS`.

The EDEM algorithm (:func:`edem.solver.run`) measures the springs at a pose, assembles one time
point's contact problem (:class:`ContactStep`: the candidates' rows and element law, the
ligaments, the shear springs) and hands it to the scene's bed, which owns

* its static solve at the time point (:meth:`Bed.solve`), the unilateral equilibrium
  (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs);
* its Kelvin-Voigt steps (docs/method.md#4-viscoelastic-edem-thesis-chapter-6): the thesis's increment
  (:meth:`Bed.viscoelastic_increment`); for the contact set of the creeping displacement, its solve
  of a step that carries a :class:`edem.viscoelastic.Creep`, the springs' gaps after it
  (:meth:`Bed.spring_gaps_mm`) and the force-free pose of an unloaded time point (:meth:`Bed.force_free`);
* its warnings, at every time point (:meth:`Bed.step_warnings`) and at the first
  (:meth:`Bed.first_step_warnings`: the weak-DOF rule, the coupled layer's resolution);
* its re-measure rule (:meth:`Bed.remeasured_imbalance`): DEM re-measures the independent
  springs at the solved pose; the coupled layer's forces are not a function of each spring's
  length, so there is nothing to re-measure;
* its refusals of a cartilage it cannot take (:meth:`Bed.check`, called by the one cartilage
  validator :func:`edem.scene.cartilage_from_table`);
* its own ``[cartilage]`` keys: declared as the fields of its :attr:`Bed.Keys` dataclass, read
  and checked by :meth:`Bed.read_keys` (through :func:`read_bed`, which refuses another bed's
  keys), held by the cartilage (``Cartilage.bed_keys``) and written to summary.json by
  :func:`bed_summary`; the scene files, :meth:`edem.scene.Scene.from_arrays` and the campaigns'
  FE sides (which never see them) take the keys from :func:`bed_keys`;
* its label, as the reports and the command line name it (:attr:`Bed.label`).

``[cartilage] coupling`` names the bed (:data:`BEDS`): the independent springs by default, or the
coupled layer (its keys ``thin_layer_symbol``, a name of :data:`edem.layer_symbols.LAYER_SYMBOLS`,
``thin_layer_smoothing_resolution`` and ``thin_layer_stack``).

To add a bed, with or without keys of its own: one subclass of :class:`Bed` here, added to
:data:`BEDS`, plus its tests.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import asdict, dataclass, fields, replace
from typing import Any, ClassVar

import numpy as np

from edem.consistency import remeasured_imbalance
from geometries.errors import InputError, SolverError
from edem.laws import LAWS, ElementLaw, LinearElements
from edem.mechanics import DOF_NAMES, ShearTerms, UnilateralSolution, assemble_stiffness, solve_unilateral, unrestrained_dofs
from edem.raycast import RayCaster
from edem.springs import Cartilage, Placement, SpringGeometry
from edem.tables import SceneTable
from edem.layer_symbols import LAYER_SYMBOLS, taylor_coefficients
from edem.thin_layer_contact import ContactHistory, CoupledStep, coupled_layer_mesh
from edem.viscoelastic import Creep, touch_motion


@dataclass(frozen=True)
class ContactStep:
    """One time point's contact problem as the EDEM algorithm assembled it; the bed solves it.

    Elements: the n_c candidate springs (in ``geometry.candidate_index`` order), then the n_l
    ligaments.
    """

    geometry: SpringGeometry  # M's springs at the pose the step was measured at
    directions: np.ndarray  # (n_c + n_l, 6) generalised directions g = (n, (c - G) x n)
    law: ElementLaw  # s(delta) of the n_c + n_l elements
    stored_normal_n: np.ndarray  # (n_c,) normal part of the forces committed at the previous step (the EDEM push-back)
    ligament_rows: np.ndarray  # (n_l, 6)
    ligament_law: LinearElements
    shear: ShearTerms | None  # the candidates' shear springs (None: frictionless)
    fixed_dofs: tuple[str, ...]
    length_scale_mm: float  # RMS distance of the springs from G: weighs moments against forces
    # a Kelvin-Voigt step with the contact set of the creeping displacement (edem.viscoelastic); None: elastic
    creep: Creep | None = None

    @property
    def n_candidates(self) -> int:
        return int(self.geometry.candidate_index.size)


def weak_dofs_warning(
    directions: np.ndarray,
    law: ElementLaw,
    shear: ShearTerms | None,
    solution: UnilateralSolution,
    fixed_dofs: tuple[str, ...],
    length_scale_mm: float,
    ratio: float = 1e-4,
    coupled: bool = False,
) -> list[str]:
    """Warn about free DOFs that are restrained only by round-off-like stiffness (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs).

    A faceted cylinder's normals tilt slightly off radial, so sliding along its axis is not
    exactly singular but about 1e-5 as stiff as the rest: the solve succeeds and the body drifts.
    ``coupled``: the active rows are weighed by their columns' small-strain stiffness. A coupled
    layer's surface moves by C f, not by g . u, so its columns' law at g . u means nothing (and
    is not finite past a log column's range); the layer restrains the same DOFs as its rows.
    """
    approach = np.zeros(directions.shape[0]) if coupled else directions @ solution.displacement
    _, stiffness = law.force_and_stiffness(approach)
    k = assemble_stiffness(directions, stiffness, solution.active, shear)
    free = np.array([d not in fixed_dofs for d in DOF_NAMES])
    weak = unrestrained_dofs(k, free, length_scale_mm, rtol=ratio)
    if not weak:
        return []
    return [
        f"the contact barely resists motion along {', '.join(weak)} (stiffness below {ratio:g} of the largest, "
        "e.g. sliding along a faceted cylinder's axis): consider fixing these DOFs in [constraints] fixed_dofs"
    ]


@dataclass(frozen=True)
class NoKeys:
    """The keys of a bed that reads none of its own."""


class Bed(ABC):
    """A spring bed over one run of a scene (it may keep state from one time point to the next).

    ``scene`` is the :class:`edem.scene.Scene` being run and ``caster`` its fixed body's ray
    caster. The methods of one time point take its :class:`ContactStep`; forces are N, moments
    N mm, displacements mm and rad, loads (6,) the force and the moment about G.
    """

    #: the value of ``[cartilage] coupling`` that picks this bed (its key in :data:`BEDS`)
    coupling: ClassVar[str]
    #: the bed as the reports and messages name it ("independent springs", "coupled layer")
    label: ClassVar[str]
    #: the bed's own ``[cartilage]`` keys: a frozen dataclass whose fields are the keys, with
    #: their defaults (a scene that names the bed without them gets those)
    Keys: ClassVar[type] = NoKeys

    def __init__(self, scene, caster: RayCaster) -> None:
        self.scene = scene
        self.caster = caster

    @classmethod
    def own_keys(cls) -> tuple[str, ...]:
        """The names of the bed's own ``[cartilage]`` keys (the fields of :attr:`Keys`)."""
        return tuple(f.name for f in fields(cls.Keys))

    @classmethod
    def read_keys(cls, table: SceneTable) -> Any:
        """The bed's own keys from ``table`` (``[cartilage]``), checked: a :attr:`Keys`.
        InputError naming the key for a value the bed cannot take."""
        return cls.Keys()

    @classmethod
    def text(cls, keys: Any) -> str:
        """The bed with its keys ``keys`` (a :attr:`Keys`), for a run's one-line report."""
        return cls.label

    @classmethod
    def check(cls, cartilage: Cartilage, table: SceneTable) -> None:
        """Raise InputError when the bed cannot take this cartilage (the errors name ``table``'s keys)."""

    @abstractmethod
    def solve(self, step: ContactStep, load: np.ndarray) -> UnilateralSolution:
        """Unilateral equilibrium under ``load`` (6,): u (6,), element forces and active set over
        the candidates then the ligaments. SolverError where there is none."""

    @abstractmethod
    def viscoelastic_increment(
        self, step: ContactStep, elastic: UnilateralSolution, previous_load: np.ndarray, load: np.ndarray, weights: tuple[float, float]
    ) -> tuple[np.ndarray, np.ndarray]:
        """Kelvin-Voigt increment u = K^-1 [phi (T_{k-1} - p) + psi (T_k - T_{k-1})] (eq. 6.18).

        ``elastic``: :meth:`solve`'s answer under T_k = ``load`` at this time point; ``weights``
        (phi, psi) of :func:`edem.viscoelastic.integrator_weights`. Returns u (6,) and the elastic
        element forces (n_c + n_l,) to commit.
        """

    @abstractmethod
    def spring_gaps_mm(self, step: ContactStep, solution: UnilateralSolution) -> np.ndarray:
        """The candidates' gaps (n_c,) in mm after :meth:`solve` of a creeping ``step``: 0 in
        contact, the opening out of it."""

    @abstractmethod
    def force_free(self, step: ContactStep, direction: np.ndarray | None) -> UnilateralSolution | None:
        """An unloaded time point of a creeping ``step``: M moved along ``direction`` (3,) to touch
        the cartilage with no force anywhere (:func:`edem.viscoelastic.touch_motion`); None where
        no pose on that line is force-free (the ligaments hold M against the cartilage)."""

    def step_warnings(self, step: ContactStep, solution: UnilateralSolution, where: str) -> list[str]:
        """Warnings about one time point's solution (``where`` names it)."""
        return []

    def first_step_warnings(self, step: ContactStep, solution: UnilateralSolution) -> list[str]:
        """Warnings said once, at the first time point: DOFs the contact barely restrains."""
        return weak_dofs_warning(step.directions, step.law, step.shear, solution, step.fixed_dofs, step.length_scale_mm)

    def remeasured_imbalance(
        self, step: ContactStep, solution: UnilateralSolution, u: np.ndarray, mobile: Placement, fixed: Placement, load: np.ndarray
    ) -> float | None:
        """DEM: the load fraction the bed measured again at M's solved pose ``mobile`` leaves
        unbalanced (:func:`edem.consistency.remeasured_imbalance`); None where the bed has no
        re-measure."""
        return None


class IndependentSprings(Bed):
    """Independent springs (the thesis's bed): each spring's force depends on its own length only."""

    coupling = "none"
    label = "independent springs"

    def __init__(self, scene, caster: RayCaster) -> None:
        super().__init__(scene, caster)
        # The previous time point's solution (EDEM: its increment; DEM: its displacement from M's
        # initial pose), where the next solve starts (None: the first time point, from u = 0).
        self.previous_displacement: np.ndarray | None = None

    def solve(self, step, load):
        law = step.law if step.creep is None else step.creep.law(step)
        solution = solve_unilateral(
            step.directions, law, load, fixed_dofs=step.fixed_dofs, shear=step.shear, length_scale_mm=step.length_scale_mm,
            start_displacement=self.previous_displacement,
        )
        self.previous_displacement = solution.displacement
        return solution

    def spring_gaps_mm(self, step, solution):
        law, n_c = step.creep.law(step), step.n_candidates
        # an independent spring's force is -(c0 k) x its gap out of contact
        return np.maximum(-solution.element_force_n[:n_c], 0.0) / law.stiffness_n_per_mm[:n_c]

    def force_free(self, step, direction):
        law, n_c = step.creep.law(step), step.n_candidates
        stiffness = law.stiffness_n_per_mm[:n_c]
        u = touch_motion(-law.offset_n[:n_c] / stiffness, step.directions[:n_c], step.ligament_rows, step.ligament_law, direction)
        if u is None:
            return None
        force, _ = law.force_and_stiffness(step.directions @ u)
        return UnilateralSolution(u, force, np.zeros(force.shape[0], bool), 0, 0.0, 0.0)

    def viscoelastic_increment(self, step, elastic, previous_load, load, weights):
        """Every spring that holds an elastic force creeps with its dashpot over the step (its total
        force may vanish, e.g. when the load goes to zero, while its elastic force relaxes), so it
        stays in the increment's set whatever the quasi-static solve under T_k left active."""
        phi, psi = weights
        directions, law, shear = step.directions, step.law, step.shear
        force0, stiffness0 = law.force_and_stiffness(np.zeros(directions.shape[0]))
        active = elastic.active | (force0 > 0)
        free = np.array([d not in step.fixed_dofs for d in DOF_NAMES])
        u = np.zeros(6)
        if np.any(active) and (phi or psi):
            n_shear = 0 if shear is None else shear.normals.shape[0]
            pushback = directions.T @ np.where(active, force0, 0.0)
            if shear is not None:
                pushback = pushback + shear.generalised_force(np.zeros(6), active[:n_shear])
            k = assemble_stiffness(directions, stiffness0, active, shear)
            rhs = phi * (previous_load - pushback) + psi * (load - previous_load)
            u[free] = np.linalg.lstsq(k[np.ix_(free, free)], rhs[free], rcond=None)[0]
        force, _ = law.force_and_stiffness(directions @ u)
        return u, np.where(active, np.maximum(force, 0.0), 0.0)

    def remeasured_imbalance(self, step, solution, u, mobile, fixed, load):
        scene = self.scene
        imbalance, scale = remeasured_imbalance(
            pose=mobile, fixed_pose=fixed, initial=step.geometry, spring_centroid_mm=scene.spring_centroid_mm, spring_normal=scene.spring_normal,
            spring_area_mm2=scene.spring_area_mm2, caster=self.caster, cartilage=scene.cartilage, ligaments=scene.ligaments,
            reference_point_mm=scene.reference_point_mm, shear=step.shear, u=u, active=solution.active,
            model_force_n=np.where(solution.active, solution.element_force_n, 0.0), load=load,
            free=np.array([d not in step.fixed_dofs for d in DOF_NAMES]), length_scale_mm=step.length_scale_mm,
        )
        return imbalance / scale if scale > 0 else 0.0


#: ``[cartilage] thin_layer_stack``: how the coupled layer takes a layer on each side
THIN_LAYER_STACKS = ("sandwich", "lumped")


class CoupledThinLayer(Bed):
    """The coupled thin layer (:mod:`edem.thin_layer_contact`): the springs' forces answer the
    layer's deflection through its compliance (symbol ``cartilage.thin_layer_symbol``), built
    per time point on the spring-bearing surface."""

    coupling = "thin-layer"
    label = "coupled layer"

    @dataclass(frozen=True)
    class Keys:
        """The coupled layer's ``[cartilage]`` keys (README.md#scene-files)."""

        thin_layer_symbol: str = "pade"  # a name of edem.layer_symbols.LAYER_SYMBOLS (Cartilage.layer_symbol)
        # cells of the coarse smoothing space per smoothing length (0: the springs' own vertices; edem.coarse_space)
        thin_layer_smoothing_resolution: float = 0.0
        # where both sides have a layer (edem.thickness): "sandwich", each layer bonded to its bone and
        # frictionless against the other (their compliances add), or "lumped", one layer of their summed
        # thickness (the model error docs/method.md measures, kept for comparison)
        thin_layer_stack: str = "sandwich"

    def __init__(self, scene, caster: RayCaster) -> None:
        super().__init__(scene, caster)
        self.mesh = coupled_layer_mesh(scene)
        # The last time points' forces and gaps: the next solve's first guess.
        self.history = ContactHistory(scene.spring_area_mm2.shape[0])
        self.layer: CoupledStep | None = None  # the time point last solved
        self._stiffer: tuple[float, Cartilage] | None = None  # (c0, the cartilage c0 times stiffer) of creeping steps

    @classmethod
    def read_keys(cls, table: SceneTable) -> Keys:
        default = cls.Keys()
        return cls.Keys(
            table.string("thin_layer_symbol", default.thin_layer_symbol, tuple(LAYER_SYMBOLS)),
            table.number("thin_layer_smoothing_resolution", default.thin_layer_smoothing_resolution, nonnegative=True,
                         what="cells of the coarse smoothing space per smoothing length (>= 0; 0: the springs' own mesh)"),
            table.string("thin_layer_stack", default.thin_layer_stack, THIN_LAYER_STACKS),
        )

    @classmethod
    def text(cls, keys: Keys) -> str:
        coarse = f", coarse smoothing at {keys.thin_layer_smoothing_resolution:g} cells per smoothing length" if keys.thin_layer_smoothing_resolution else ""
        lumped = ", both sides' layers lumped into one" if keys.thin_layer_stack == "lumped" else ""
        return f"{cls.label} ({keys.thin_layer_symbol}{coarse}{lumped})"

    @classmethod
    def check(cls, cartilage: Cartilage, table: SceneTable) -> None:
        law, symbol = cartilage.spring_law, cartilage.bed_keys.thin_layer_symbol
        if law.thin_layer is None:
            coupled_laws = " or ".join(f'"{name}"' for name, each in LAWS.items() if each.thin_layer is not None)
            raise table.error(
                "coupling", f"the {cartilage.law} law has no thin-layer form",
                f'law = {coupled_laws} with coupling = "{cls.coupling}", or coupling = "{IndependentSprings.coupling}"',
            )
        if law.nonlinear:
            # Linearised at a force f, a nonlinear column takes up to (G/E') h/(G A) off the local
            # compliance (ContactLaw.column_excess_mm: t/(A E') (1 - exp(-f/(A E')))), which must stay
            # positive for every f: the symbol's local part must be at least G/E' (up to round-off).
            local, confined = cartilage.layer_symbol.local, taylor_coefficients(cartilage.poissons_ratio)[0]
            if local < confined * (1.0 - 1e-12):
                raise table.error(
                    "thin_layer_symbol" if table.has("thin_layer_symbol") else "law",
                    f"the {cartilage.law} law's columns cannot be linearised on the {symbol} symbol at Poisson's ratio "
                    f"{cartilage.poissons_ratio:g}: its local compliance, {local:.3g} h/G, is below the column's G/E' = {confined:.3g} h/G",
                    f'law = "gap" with the coupling, or coupling = "{IndependentSprings.coupling}" with law = "{cartilage.law}" '
                    "(the Pade symbol takes it at nu = 0, 1/4 and above)",
                )

    def _build(self, step: ContactStep) -> None:
        """The time point's layer (``self.layer``).

        A creeping step (:class:`edem.viscoelastic.Creep`) is the elastic one with the layer's
        compliance over c0 (its modulus c0 E), the carried forces c0 times theirs, the history's
        push-back -S_n over the layer's springs and a carried law's gaps."""
        n_c, creep = step.n_candidates, step.creep
        cartilage, carried, history, gap = self.scene.cartilage, step.stored_normal_n, None, None
        if creep is not None:
            if self._stiffer is None or self._stiffer[0] != creep.scale:  # (one per scale: the layer is built once for it)
                self._stiffer = creep.scale, replace(cartilage, youngs_modulus_mpa=creep.scale * cartilage.youngs_modulus_mpa)
            cartilage, carried = self._stiffer[1], creep.scale * carried
            history, gap = -creep.normal_history_n(step.geometry.normal), creep.gap_mm
        self.layer = CoupledStep.build(self.mesh, step.geometry, cartilage, carried, step.directions[:n_c], step.ligament_rows, step.ligament_law,
                                       history, gap)

    def solve(self, step, load):
        self._build(step)
        first = self._springs_contact(step, load) if self.history.recorded < 2 else None
        solution = self.layer.solve(load, step.fixed_dofs, step.shear, step.length_scale_mm, self.history, first)
        self._release(step, solution)
        return solution

    @staticmethod
    def _springs_contact(step: ContactStep, load: np.ndarray) -> np.ndarray | None:
        """The independent springs' contact set under ``load`` ((n_c,) bool over the candidates):
        the coupled solve's first iterate while the history has no two time points to extrapolate
        from. The springs are the layer's long-wave limit (a uniform pressure deflects both alike),
        so their set lies near the layer's: on the 3k-spring gap-law stance of
        ``benchmarks/bench_thin_layer.py`` the first two time points took 3 + 3 active-set
        iterations instead of 5 + 6 (the two-pole 4 + 5 instead of 8 + 9), for two spring solves.
        None where the springs find no equilibrium (the coupled solve then starts as it would)."""
        law = step.law if step.creep is None else step.creep.law(step)
        try:
            springs = solve_unilateral(step.directions, law, load, fixed_dofs=step.fixed_dofs, shear=step.shear,
                                       length_scale_mm=step.length_scale_mm)
        except SolverError:
            return None
        return springs.active[: step.n_candidates]

    def _release(self, step: ContactStep, solution: UnilateralSolution) -> None:
        self.history.record(step.geometry.candidate_index, solution)

    def spring_gaps_mm(self, step, solution):
        return solution.gap_mm

    def force_free(self, step, direction):
        self._build(step)
        solution = self.layer.force_free(direction)
        if solution is not None:
            self._release(step, solution)
        return solution

    def viscoelastic_increment(self, step, elastic, previous_load, load, weights):
        return self.layer.viscoelastic_increment(elastic, step.stored_normal_n, previous_load, load, weights, step.shear, step.fixed_dofs)

    def step_warnings(self, step, solution, where):
        if solution.max_penetration_mm > 1e-9 * self.scene.cartilage.max_spring_length_mm:
            return [f"{where}: the layer's surface penetrates the fixed body by {solution.max_penetration_mm:.3g} mm out of contact"]
        return []

    def first_step_warnings(self, step, solution):
        return self.layer.resolution_warning(self.mesh) + weak_dofs_warning(
            step.directions, step.law, step.shear, solution, step.fixed_dofs, step.length_scale_mm, coupled=True
        )


#: the beds by ``[cartilage] coupling``
BEDS: dict[str, type[Bed]] = {bed.coupling: bed for bed in (IndependentSprings, CoupledThinLayer)}
#: the bed of a scene that names none
DEFAULT_COUPLING = IndependentSprings.coupling


def bed_keys() -> tuple[str, ...]:
    """The ``[cartilage]`` keys the beds read: ``coupling``, then every registered bed's own keys."""
    return ("coupling", *dict.fromkeys(key for bed in BEDS.values() for key in bed.own_keys()))


def read_bed(table: SceneTable) -> tuple[type[Bed], Any]:
    """The bed ``table``'s (``[cartilage]``'s) ``coupling`` names (:data:`DEFAULT_COUPLING` where
    it names none) and its own keys, checked (:meth:`Bed.read_keys`). InputError naming the key for
    an unknown bed, and for another bed's key given to this one."""
    bed = BEDS[table.string("coupling", DEFAULT_COUPLING, tuple(BEDS))]
    for other in BEDS.values():
        for key in other.own_keys():
            if table.has(key) and key not in bed.own_keys():
                raise table.error(key, f"{key} only applies to the {other.label}", f'coupling = "{other.coupling}" with it, or no {key}')
    return bed, bed.read_keys(table)


def on_bed(cartilage: Cartilage, coupling: str, **keys: Any) -> Cartilage:
    """``cartilage`` on the bed ``coupling`` with its own ``keys`` (the others at their defaults),
    checked as a scene's ``[cartilage]`` is (InputError naming the key)."""
    table = SceneTable({"coupling": coupling, **keys}, "<arrays>", "", None)
    bed, own = read_bed(table)
    placed = replace(cartilage, coupling=bed.coupling, bed_keys=own)
    bed.check(placed, table)
    return placed


def bed_summary(cartilage: Cartilage) -> dict[str, Any]:
    """summary.json's bed (docs/result-format.md): ``coupling`` and every bed's own keys, with the
    cartilage's values for its bed's and null for the others'."""
    own = asdict(cartilage.bed_keys)
    return {"coupling": cartilage.coupling, **{key: own.get(key) for key in bed_keys()[1:]}}


def bed_text(cartilage: Cartilage) -> str:
    """The bed a run used, with its keys, for its one-line report (:meth:`Bed.text`)."""
    return bed_class(cartilage.coupling).text(cartilage.bed_keys)


def bed_class(coupling: str) -> type[Bed]:
    """The bed named by ``[cartilage] coupling``; InputError naming the key for an unknown one."""
    if coupling not in BEDS:
        raise InputError(f"unknown bed {coupling!r}", key="cartilage.coupling", expected="one of " + ", ".join(BEDS))
    return BEDS[coupling]


def scene_bed(scene, caster: RayCaster) -> Bed:
    """The bed of a scene's cartilage for one run (``scene``: :class:`edem.scene.Scene`)."""
    return bed_class(scene.cartilage.coupling)(scene, caster)
