"""How the FE reference of a scene steps through its time points: one seam for every material's
time dependence (docs/method.md#6-the-fe-reference-and-its-discrete-twins).

:func:`fem_reference.scene_run.run_scene` walks the time points in order. Per time point it
builds the model's solid and the obstacle, finds the free rigid motions, builds (or reuses) the
dolfinx mesh and a :class:`FEContactProblem` without history (mesh, material, obstacle, load,
free motions), and writes the result. A :class:`TimeStepping` decides all that depends on time.
An implementation provides:

* :meth:`~TimeStepping.time_points`: the time points to solve for those asked for (a history
  needs every one up to the last asked for);
* :meth:`~TimeStepping.start_warnings`: what the run says about its start (the first load);
* :meth:`~TimeStepping.unloaded`: at a time point with no load along the free motions, the
  bone's translation and rotation (3,) and what the body does (``"nothing to solve"``);
* :meth:`~TimeStepping.prepare`: before a loaded time point's solve, put the history into its
  problem (a warm start, a shifted gap); refuse with :class:`geometries.errors.InputError`, naming
  ``point.where``, a time point the history cannot take (another mesh);
* :meth:`~TimeStepping.solve`: solve the prepared problem and advance the history. It returns an
  :class:`FEContactResult` (:meth:`fem_reference.contact_setup.ContactSetup.result` builds one)
  whose ``bone_displacement_mm`` / ``bone_rotation_rad`` are the bone's motion to report, whose
  pressure, area and forces are the time point's, and whose ``fields`` hold at least ``"setup"``
  (the :class:`ContactSetup` of ``point.mesh``) and ``"pressure"`` (the contact pressure, a UFL
  expression on it), from which the contact area on M is integrated. Errors are named after the
  time point by the caller;
* :meth:`~TimeStepping.summary`: its keys in summary.json.

Implementations: :class:`ElasticStepping` (each time point its own elastic problem, warm-started
from the previous one on the same geometry), :class:`KelvinVoigtStepping` (the Kelvin-Voigt
continuum of :mod:`fem_reference.viscoelastic`: a history on one mesh, each time point an
elastic contact problem for v = c0 u - h with a shifted gap) and :class:`BiphasicStepping` (the
biphasic layer of :mod:`fem_reference.biphasic_contact`: a history of (u, p) on one mesh, each time
point a Taylor-Hood contact problem whose bulk terms are the flow step's). :func:`time_stepping`
picks one for a scene.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fem_reference.biphasic_contact import BiphasicContactHistory
from fem_reference.contact import solve_from_warm_start
from fem_reference.models import FE_MODELS, FEGeometry
from fem_reference.problem import FEContactProblem, FEContactResult, FEMesh
from fem_reference.progress import SolveProgress
from fem_reference.settings import FESettings
from fem_reference.viscoelastic import KelvinVoigtHistory, first_load_warning
from geometries.errors import InputError
from geometries.fe_solids import CONTACT_TAG, FREE_TAG


@dataclass
class TimePoint:
    """One time point of a run, as :func:`fem_reference.scene_run.run_scene` hands it over."""

    index: int
    time_s: float
    where: str  # how messages name it: "time point k (t = ... s)"
    geometry: FEGeometry  # the model's solid and the obstacle (F at this time point's pose)
    force_n: np.ndarray  # (3,) the applied force
    comm: Any  # the MPI communicator of the solves
    progress: SolveProgress | None  # progress lines from inside the solves (None: none)
    mesh: FEMesh | None = None  # the run's current mesh (a loaded time point's own; None before any)
    mesh_key: Any = None  # what it was built for: geometry.key, or geometry.key[0] when it serves every pose

    def solve_progress(self, label: str | None = None) -> SolveProgress | None:
        """The progress of one solve at this time point, labelled ``label`` (default :attr:`where`)."""
        return None if self.progress is None else self.progress.for_solve(self.where if label is None else label)


class TimeStepping(ABC):
    """How a run steps through time (module docstring: what an implementation provides)."""

    def time_points(self, selected: Sequence[int]) -> list[int]:
        """The time points to solve, in order, for the ``selected`` ones (sorted)."""
        return list(selected)

    def start_warnings(self, force_n: np.ndarray) -> list[str]:
        """Warnings about the start, given the first time point's force (3,)."""
        return []

    @abstractmethod
    def unloaded(self, point: TimePoint) -> tuple[np.ndarray, np.ndarray, str]:
        """(translation (3,) mm, rotation (3,) rad, what the body does) at a time point with no load
        along the free motions (``point.force_n`` zero, or carried by the constraints)."""

    @abstractmethod
    def prepare(self, point: TimePoint, problem: FEContactProblem) -> None:
        """Put the history into the loaded time point's ``problem`` (solved on ``point.mesh``)."""

    @abstractmethod
    def solve(self, point: TimePoint, problem: FEContactProblem) -> FEContactResult:
        """Solve the prepared ``problem`` and advance the history (module docstring)."""

    def summary(self) -> dict[str, Any]:
        """Its keys in summary.json."""
        return {}


class ElasticStepping(TimeStepping):
    """The elastic FE: each time point independent (the DEM convention: the displacement of G from
    the initial pose of that time point). Consecutive time points with the same geometry and pose
    start Newton from the previous solution scaled to the new load (its translation scaled too
    when ``warm_start_scales_with_load``: exact for a slab whose contact set does not change);
    a warm start that fails is retried from the default start."""

    def __init__(self, warm_start_scales_with_load: bool) -> None:
        self.warm_start_scales_with_load = warm_start_scales_with_load
        self.previous: dict | None = None  # the last solve: geometry key, motion, field, force

    def unloaded(self, point: TimePoint) -> tuple[np.ndarray, np.ndarray, str]:
        return np.zeros(3), np.zeros(3), "nothing to solve"

    def prepare(self, point: TimePoint, problem: FEContactProblem) -> None:
        previous = self.previous
        if previous is not None and previous["key"] == point.geometry.key:
            # same mesh and obstacle: start from the previous solution, scaled to the load
            ratio = float(np.linalg.norm(point.force_n)) / max(float(np.linalg.norm(previous["force"])), 1e-300)
            problem.initial_translation_mm = previous["t"] * (ratio if self.warm_start_scales_with_load else 1.0)
            problem.initial_rotation_rad = previous["q"] * ratio
            problem.initial_field = previous["ut"] * ratio

    def solve(self, point: TimePoint, problem: FEContactProblem) -> FEContactResult:
        res = solve_from_warm_start(problem, point.comm, progress=point.solve_progress(),
                                    cold_progress=point.solve_progress(f"{point.where}, restarted cold"))
        self.previous = {"key": point.geometry.key, "t": res.bone_displacement_mm.copy(),
                         "q": res.bone_rotation_rad.copy(), "ut": res.fields["ut_owned"], "force": point.force_n}
        return res


class KelvinVoigtStepping(TimeStepping):
    """The Kelvin-Voigt continuum (:mod:`fem_reference.viscoelastic`): every time point up to the
    last asked for, in order, on one mesh. The body starts at rest at the last unloaded time point
    before the first load (else from the elastic solution under that load); a loaded time point
    is an elastic contact problem for v = c0 u - h with the shifted gap, an unloaded one lets the
    cartilage creep back. The motion reported is u's.

    ``scheme``: :data:`fem_reference.viscoelastic.TIME_SCHEMES`; ``degree``: the displacement's;
    ``scene_file``: named by the refusal of a second mesh.
    """

    def __init__(self, relaxation_time_s: float, scheme: str, degree: int, scene_file: Any) -> None:
        self.relaxation_time_s = relaxation_time_s
        self.scheme = scheme
        self.degree = degree
        self.scene_file = scene_file
        self.history: KelvinVoigtHistory | None = None  # from the first loaded time point on
        self.rest_time_s: float | None = None  # the last unloaded time point before it
        self.step: tuple = ()  # what the prepared step's commit needs: (c0, h's translation, h's rotation)

    def time_points(self, selected: Sequence[int]) -> list[int]:
        return list(range(selected[-1] + 1))  # the history needs every time point up to the last asked for

    def start_warnings(self, force_n: np.ndarray) -> list[str]:
        return first_load_warning(force_n)

    def unloaded(self, point: TimePoint) -> tuple[np.ndarray, np.ndarray, str]:
        if self.history is None:
            if not np.any(point.force_n):
                self.rest_time_s = point.time_s
            return np.zeros(3), np.zeros(3), "nothing to solve"
        self._same_mesh(point)
        translation, rotation = self.history.relax(point.time_s, point.geometry.obstacle, CONTACT_TAG)
        return translation, rotation, "the cartilage creeps back, the bone follows it without force"

    def prepare(self, point: TimePoint, problem: FEContactProblem) -> None:
        if self.history is None:
            self.history = KelvinVoigtHistory(point.mesh, self.degree, self.relaxation_time_s, self.scheme)
            if self.rest_time_s is not None:
                self.history.start_at_rest(self.rest_time_s)
        self._same_mesh(point)
        self.step = self.history.prepare(problem, point.time_s)

    def solve(self, point: TimePoint, problem: FEContactProblem) -> FEContactResult:
        res = solve_from_warm_start(problem, point.comm, progress=point.solve_progress(),
                                    cold_progress=point.solve_progress(f"{point.where}, restarted cold"))
        # the solve's unknown was v = u + tau du/dt: report u's motion
        res.bone_displacement_mm, res.bone_rotation_rad = self.history.commit(point.time_s, res, *self.step, problem)
        return res

    def summary(self) -> dict[str, Any]:
        return {"relaxation_time_s": self.relaxation_time_s, "time_scheme": self.scheme}

    def _same_mesh(self, point: TimePoint) -> None:
        same_mesh(point, self.history.mesh, "viscoelastic", self.scene_file)


def same_mesh(point: TimePoint, mesh: FEMesh, what: str, scene_file: Any) -> None:
    """A history lives on one mesh: refuse (InputError) a time point that needs another than ``mesh``.
    ``what``: the FE's name in the message, as the scene asks for it (its section)."""
    key = point.geometry.key
    if mesh is not point.mesh or point.mesh_key not in (key, key[0]):
        raise InputError(f"{point.where}: the {what} FE needs one mesh at every time point, and the FE slab follows "
                         "the joint angle", file=scene_file, key="kinematics",
                         expected=f"no [kinematics] with [{what}], or the layer model (--model layer)")


class BiphasicStepping(TimeStepping):
    """The biphasic layer (:mod:`fem_reference.biphasic_contact`): every time point up to the last
    asked for, in order, on one mesh. The body starts at rest at the last unloaded time point before
    the first load (loads are linear between time points: the first loaded step is a ramp), else
    with the undrained response to the load at the first time point. The drained matrix is the
    scene's cartilage (its Young's modulus and Poisson's ratio); the contact face drains where the
    counter-surface lets it (``counter_surface``), the free faces drain, the bonded face does not.

    ``permeability_mm4_per_n_s``, ``counter_surface``: the scene's ``[biphasic]``; ``scheme``:
    :data:`fem_reference.biphasic.TIME_SCHEMES`; ``scene_file``: named by the refusals.
    """

    def __init__(self, permeability_mm4_per_n_s: float, counter_surface: str, scheme: str, scene_file: Any) -> None:
        self.permeability_mm4_per_n_s = permeability_mm4_per_n_s
        self.counter_surface = counter_surface
        self.scheme = scheme
        self.scene_file = scene_file
        self.history: BiphasicContactHistory | None = None  # from the first loaded time point on
        self.rest_time_s: float | None = None  # the last unloaded time point before it
        self.fluid_load_fraction: dict[int, float] = {}  # per solved loaded time point

    def time_points(self, selected: Sequence[int]) -> list[int]:
        return list(range(selected[-1] + 1))  # the history needs every time point up to the last asked for

    def start_warnings(self, force_n: np.ndarray) -> list[str]:
        if not np.any(force_n):
            return []
        return ["the first time point carries a load: the biphasic FE starts with the undrained response to it (the load "
                "applied at that instant), viscoelastic EDEM's creeping contact set with the elastic solution (a load held "
                "since long before); start the load history at zero to compare them"]

    def unloaded(self, point: TimePoint) -> tuple[np.ndarray, np.ndarray, str]:
        if self.history is None:
            if not np.any(point.force_n):
                self.rest_time_s = point.time_s
            return np.zeros(3), np.zeros(3), "nothing to solve"
        raise InputError(f"{point.where}: the biphasic FE does not model unloading (the layer would swell back, free of the bone)",
                         file=self.scene_file, key="load.force_n",
                         expected="a load along the free DOFs at every time point after the first loaded one, or [fe] material = \"elastic\"")

    def prepare(self, point: TimePoint, problem: FEContactProblem) -> None:
        if self.history is None:
            self.history = BiphasicContactHistory(point.mesh, self.permeability_mm4_per_n_s, self.scheme,
                                                  self.counter_surface, drained_tags=(FREE_TAG,))
            if self.rest_time_s is not None:
                self.history.start_at_rest(self.rest_time_s)
        same_mesh(point, self.history.mesh, "biphasic", self.scene_file)
        self.history.prepare(problem, point.time_s)

    def solve(self, point: TimePoint, problem: FEContactProblem) -> FEContactResult:
        result = self.history.solve(problem, point.time_s, point.comm, point.solve_progress())
        self.fluid_load_fraction[point.index] = self.history.fluid_load_fraction[-1]
        return result

    def summary(self) -> dict[str, Any]:
        last = max(self.fluid_load_fraction, default=-1)
        return {"material": "biphasic", "permeability_mm4_per_n_s": self.permeability_mm4_per_n_s,
                "counter_surface": self.counter_surface, "time_scheme": self.scheme,
                # per time point from the first to the last solved (0 where unloaded)
                "fluid_load_fraction": [self.fluid_load_fraction.get(k, 0.0) for k in range(last + 1)]}


def time_stepping(scene: Any, settings: FESettings) -> TimeStepping:
    """The time stepping of ``scene`` (an :class:`edem.scene.Scene`): biphasic with ``[fe] material =
    "biphasic"``, else Kelvin-Voigt with ``[viscoelastic]``, else elastic. A new time-dependent
    material is one more line here."""
    if settings.biphasic is not None:
        return BiphasicStepping(settings.biphasic.permeability_mm4_per_n_s, settings.biphasic.counter_surface,
                                settings.time_scheme, scene.source)
    if scene.viscoelastic is not None:
        return KelvinVoigtStepping(float(scene.viscoelastic.relaxation_time_s), settings.time_scheme,
                                   settings.degree, scene.source)
    return ElasticStepping(FE_MODELS[settings.model].warm_start_scales_with_load)
