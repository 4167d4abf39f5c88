"""Spring beds: what carries the contact between the bones, one class per bed, registered in :data:`BEDS`.

The EDEM algorithm (:func:`edem.solver.run`) measures the springs at a pose, assembles one time
point's contact problem (:class:`ContactStep`: the candidates' rows and element law, the
ligaments, the shear springs) and hands it to the scene's bed, which owns

* its static solve at the time point (:meth:`Bed.solve`), the unilateral equilibrium
  (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs);
* its Kelvin-Voigt increment (:meth:`Bed.viscoelastic_increment`, docs/method.md#4-viscoelastic-edem-thesis-chapter-6);
* its warnings, at every time point (:meth:`Bed.step_warnings`) and at the first
  (:meth:`Bed.first_step_warnings`: the weak-DOF rule, the coupled layer's resolution);
* its re-measure rule (:meth:`Bed.remeasured_imbalance`): DEM re-measures the independent
  springs at the solved pose; the coupled layer's forces are not a function of each spring's
  length, so there is nothing to re-measure;
* its refusals of a cartilage it cannot take (:meth:`Bed.check`, called by the one cartilage
  validator :func:`edem.scene.cartilage_from_table`).

``[cartilage] coupling`` names the bed: ``"none"`` the independent springs, ``"thin-layer"`` the
coupled thin layer (``[cartilage] thin_layer_symbol`` picks its symbol among
:data:`edem.layer_symbols.LAYER_SYMBOLS`: ``pade``, ``two-pole``).

To add a bed: one subclass of :class:`Bed` here, added to :data:`BEDS`, plus its tests.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from edem.consistency import remeasured_imbalance
from geometries.errors import InputError
from edem.laws import LAWS, ElementLaw, LinearElements
from edem.mechanics import DOF_NAMES, ShearTerms, UnilateralSolution, assemble_stiffness, solve_unilateral, unrestrained_dofs
from edem.raycast import RayCaster
from edem.springs import Cartilage, Placement, SpringGeometry
from edem.tables import SceneTable
from edem.layer_symbols import LAYER_SYMBOLS, taylor_coefficients
from edem.thin_layer_contact import CoupledStep, coupled_layer_mesh


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


class Bed(ABC):
    """A spring bed over one run of a scene (it may keep state from one time point to the next).

    ``scene`` is the :class:`edem.scene.Scene` being run and ``caster`` its fixed body's ray
    caster. The methods of one time point take its :class:`ContactStep`; forces are N, moments
    N mm, displacements mm and rad, loads (6,) the force and the moment about G.
    """

    #: the value of ``[cartilage] coupling`` that picks this bed (its key in :data:`BEDS`)
    coupling: ClassVar[str]
    #: what the bed is, for messages ("the coupled thin layer")
    description: ClassVar[str]

    def __init__(self, scene, caster: RayCaster) -> None:
        self.scene = scene
        self.caster = caster

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
    description = "independent springs"

    @classmethod
    def check(cls, cartilage: Cartilage, table: SceneTable) -> None:
        for key in ("thin_layer_symbol", "thin_layer_smoothing_resolution"):
            if table.has(key):
                raise table.error(key, f"{key} only applies to the coupled thin layer", f'coupling = "{CoupledThinLayer.coupling}" with it, or no {key}')

    def __init__(self, scene, caster: RayCaster) -> None:
        super().__init__(scene, caster)
        # The previous time point's solution (EDEM: its increment; DEM: its displacement from M's
        # initial pose), where the next solve starts (None: the first time point, from u = 0).
        self.previous_displacement: np.ndarray | None = None

    def solve(self, step, load):
        solution = solve_unilateral(
            step.directions, step.law, load, fixed_dofs=step.fixed_dofs, shear=step.shear, length_scale_mm=step.length_scale_mm,
            start_displacement=self.previous_displacement,
        )
        self.previous_displacement = solution.displacement
        return solution

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


class CoupledThinLayer(Bed):
    """The coupled thin layer (:mod:`edem.thin_layer_contact`): the springs' forces answer the
    layer's deflection through its compliance (symbol ``cartilage.thin_layer_symbol``), built
    per time point on the spring-bearing surface."""

    coupling = "thin-layer"
    description = "coupled thin layer"

    def __init__(self, scene, caster: RayCaster) -> None:
        super().__init__(scene, caster)
        self.mesh = coupled_layer_mesh(scene)
        # The candidates out of contact at the previous time point: the next solve's first guess.
        self.released: np.ndarray | None = None
        self.layer: CoupledStep | None = None  # the time point last solved

    @classmethod
    def check(cls, cartilage: Cartilage, table: SceneTable) -> None:
        law, symbol = cartilage.spring_law, cartilage.thin_layer_symbol
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
            local, confined = LAYER_SYMBOLS[symbol](cartilage.poissons_ratio).local, taylor_coefficients(cartilage.poissons_ratio)[0]
            if local < confined * (1.0 - 1e-12):
                raise table.error(
                    "thin_layer_symbol" if table.has("thin_layer_symbol") else "law",
                    f"the {cartilage.law} law's columns cannot be linearised on the {symbol} symbol at Poisson's ratio "
                    f"{cartilage.poissons_ratio:g}: its local compliance, {local:.3g} h/G, is below the column's G/E' = {confined:.3g} h/G",
                    f'law = "gap" with the coupling, or coupling = "{IndependentSprings.coupling}" with law = "{cartilage.law}" '
                    "(the Pade symbol takes it at nu = 0, 1/4 and above)",
                )

    def solve(self, step, load):
        n_c = step.n_candidates
        self.layer = CoupledStep.build(
            self.mesh, step.geometry, self.scene.cartilage, step.stored_normal_n, step.directions[:n_c], step.ligament_rows, step.ligament_law
        )
        solution = self.layer.solve(load, step.fixed_dofs, step.shear, step.length_scale_mm, self.released)
        self.released = np.zeros(self.scene.spring_area_mm2.shape[0], bool)
        self.released[step.geometry.candidate_index] = ~solution.active[:n_c]
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


def bed_class(coupling: str) -> type[Bed]:
    """The bed named by ``[cartilage] coupling``; InputError naming the key for an unknown one."""
    if coupling not in BEDS:
        raise InputError(f"unknown bed {coupling!r}", key="cartilage.coupling", expected="one of " + ", ".join(BEDS))
    return BEDS[coupling]


def scene_bed(scene, caster: RayCaster) -> Bed:
    """The bed of a scene's cartilage for one run (``scene``: :class:`edem.scene.Scene`)."""
    return bed_class(scene.cartilage.coupling)(scene, caster)
