"""A DEM/EDEM run's result: the state of each time point and the result contract it writes
(:class:`edem.resultdir.RunOutput`: summary, time series rows, frames; :mod:`edem.resultdir` owns
the format and its one writer, :func:`edem.resultdir.write_run`)."""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from edem.loads import JointKinematics
from edem.opensim_model import BodyPoses
from edem.resultdir import TIMESERIES_COLUMNS, Frame, Provenance, SurfaceFrame, timeseries_row, write_pvd, write_run
from edem.scene import Scene
from edem.beds import bed_summary
from edem.preflight import Preflight
from edem.springs import Placement
from edem.thickness import thickness_summary

__all__ = ["TIMESERIES_COLUMNS", "RunResult", "StepResult", "write_pvd", "write_results"]


@dataclass
class StepResult:
    """One time point: the state every output file is written from (docs/result-format.md)."""

    step: int
    time_s: float
    force_n: np.ndarray  # applied load (3,)
    moment_nmm: np.ndarray
    displacement_mm: np.ndarray  # of G from its initial pose (EDEM: accumulated; DEM: this point)
    rotation_rad: np.ndarray  # rotation vector of M from its initial pose
    pressure_mpa: np.ndarray  # (n_springs,) normal contact pressure (elastic + viscous), 0 out of contact
    viscous_pressure_mpa: np.ndarray  # (n_springs,) the dashpots' share of it (0 without [viscoelastic])
    spring_length_mm: np.ndarray  # (n_springs,) at the start of the step, +inf where no hit
    in_contact: np.ndarray  # (n_springs,) bool
    ligament_force_n: np.ndarray  # (n_ligaments,) tension
    iterations: int
    force_residual_n: float
    moment_residual_nmm: float
    mobile_placement: Placement  # pose of M after the step (for the pressure maps)
    fixed_placement: Placement
    area_mm2: np.ndarray  # (n_springs,) spring areas
    # DEM: the load fraction the springs measured again at the solved pose leave unbalanced (None: EDEM)
    remeasured_imbalance: float | None = None
    # sum of p A n over the springs (N), its moment about G (N mm) and the centre of pressure (mm),
    # springs where the solve measured them (so they balance the load with ligaments and constraints)
    contact_force_n: np.ndarray = field(default_factory=lambda: np.zeros(3))
    contact_moment_nmm: np.ndarray = field(default_factory=lambda: np.zeros(3))
    centre_of_pressure_mm: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @functools.cached_property
    def contact_area_mm2(self) -> float:
        # cached: the summary, the time series row and the mean pressure each ask for it (a
        # step's arrays are never changed once it is made)
        return float(self.area_mm2[self.in_contact].sum())

    @property
    def peak_pressure_mpa(self) -> float:
        return float(self.pressure_mpa.max(initial=0.0))

    @property
    def mean_pressure_mpa(self) -> float:
        """Total normal contact force over the contact area."""
        area = self.contact_area_mm2
        return float((self.pressure_mpa * self.area_mm2).sum() / area) if area > 0 else 0.0


@dataclass
class RunResult:
    """Every time point of a DEM/EDEM run, and its result directory's content (the contract of
    :class:`edem.resultdir.RunOutput`)."""

    #: the time series is also written as timeseries.sto (OpenSim)
    opensim_sto: ClassVar[bool] = True

    scene: Scene
    method: str
    steps: list[StepResult]
    wall_time_s: float  # the solve of the time points (their geometry, solves and results)
    warnings: list[str]
    seconds: dict[str, float]  # wall time of the geometry stage (ray casting) and of the solves
    preflight: Preflight | None = None  # what the springs saw before the first solve (edem.preflight)
    setup_time_s: float = 0.0  # before the first time point: the ray caster, the bed, the pre-flight, lazy imports

    @property
    def n_springs(self) -> int:
        return int(self.scene.spring_area_mm2.shape[0])

    def summary(self) -> dict[str, Any]:
        """The summary.json content (the common keys, plus the law and the moment residual)."""
        steps = self.steps
        last = steps[-1]
        return {
            "scene": self.scene.name,
            "method": self.method,
            "steps": len(steps),
            "n_springs": self.n_springs,
            "wall_time_s": self.wall_time_s,
            "setup_time_s": self.setup_time_s,
            "peak_pressure_mpa": max(s.peak_pressure_mpa for s in steps),
            "max_contact_area_mm2": max(s.contact_area_mm2 for s in steps),
            "final_displacement_mm": [float(x) for x in last.displacement_mm],
            "final_rotation_rad": [float(x) for x in last.rotation_rad],
            "max_force_residual_n": max(s.force_residual_n for s in steps),
            "max_moment_residual_nmm": max(s.moment_residual_nmm for s in steps),
            "law": self.scene.cartilage.law,
            # the bed (the built-in scenes' defaults differ: the standing and toe-off ones couple, the stances do not)
            **bed_summary(self.scene.cartilage),
            "warnings": list(self.scene.warnings) + list(self.warnings),
            **thickness_summary(self.scene.cartilage.layers),  # measured thickness only
            **self._viscoelastic_summary(),
            **({} if self.preflight is None else {"preflight": self.preflight.as_dict()}),
        }

    def _viscoelastic_summary(self) -> dict[str, Any]:
        """The Kelvin-Voigt springs of a viscoelastic EDEM run (docs/method.md#4-viscoelastic-edem-thesis-chapter-6); none otherwise."""
        viscous = self.scene.viscoelastic
        if viscous is None or self.method != "edem":
            return {}
        return {"relaxation_time_s": viscous.relaxation_time_s, "contact_set": viscous.contact_set, "integrator": viscous.integrator}

    def timeseries_rows(self) -> list[dict[str, float]]:
        """One timeseries.csv row per time point of the run: the common columns, then the joint's
        pose (joint_angle_deg, or coord_<name> of an OpenSim model in rad or m), the contact resultant
        sum p A n (N) and its moment about G (N mm), the centre of pressure (mm; G when nothing is in
        contact) and each ligament's tension (N); DEM adds remeasured_imbalance (edem.consistency).
        n points from M to F: the resultant is the load the contact carries, which balances the
        applied load with the ligaments and the constraints."""
        rows = []
        kinematics = self.scene.kinematics
        for s in self.steps:
            row = timeseries_row(s.step, s.time_s, s.force_n, s.peak_pressure_mpa, s.mean_pressure_mpa, s.contact_area_mm2,
                                 s.displacement_mm, s.rotation_rad, s.iterations, s.force_residual_n)
            if isinstance(kinematics, JointKinematics):
                row["joint_angle_deg"] = float(np.degrees(kinematics.angle_rad[s.step]))
            elif isinstance(kinematics, BodyPoses):
                row.update({f"coord_{name}": float(values[s.step]) for name, values in kinematics.coordinates.items()})
            row.update(zip(("contact_force_x_n", "contact_force_y_n", "contact_force_z_n"), s.contact_force_n))
            row.update(zip(("contact_moment_x_nmm", "contact_moment_y_nmm", "contact_moment_z_nmm"), s.contact_moment_nmm))
            row.update(zip(("cop_x_mm", "cop_y_mm", "cop_z_mm"), s.centre_of_pressure_mm))
            row.update({f"ligament_{lig.name}_n": float(f) for lig, f in zip(self.scene.ligaments, np.maximum(s.ligament_force_n, 0.0))})
            if s.remeasured_imbalance is not None:
                row["remeasured_imbalance"] = float(s.remeasured_imbalance)
            rows.append(row)
        return rows

    def frames(self, positions: Sequence[int] | None = None) -> Sequence[Frame]:
        """The pressure maps of the steps at ``positions`` in ``steps`` (default: all), each made
        when it is read (a writer holds one at a time): the mobile surface at the step's pose with
        cell data pressure_mpa, spring_length_mm (0 where the ray found nothing: see ray_hit),
        in_contact and ray_hit (0/1), and with measured thickness thickness_mm (M's layer).
        Degenerate triangles carry no spring: 0 everywhere."""
        return _Frames(self._frame, self.steps if positions is None else [self.steps[k] for k in positions])

    def _frame(self, s: StepResult) -> Frame:
        scene = self.scene
        spring_triangle = scene.spring_triangle
        n_tri = scene.mobile.triangles.shape[0]
        every = len(spring_triangle) == n_tri  # (a spring on each triangle, in their order: no scatter)

        def on_triangles(values: np.ndarray, dtype: type) -> np.ndarray:
            if every:
                return values.astype(dtype)
            out = np.zeros(n_tri, dtype)
            out[spring_triangle] = values
            return out

        hit = np.isfinite(s.spring_length_mm)
        cells = {"pressure_mpa": on_triangles(s.pressure_mpa, np.float64),
                 "spring_length_mm": on_triangles(np.where(hit, s.spring_length_mm, 0.0), np.float64),
                 "in_contact": on_triangles(s.in_contact, np.int8), "ray_hit": on_triangles(hit, np.int8)}
        points = s.mobile_placement.points(scene.mobile.vertices_mm)
        if scene.cartilage.layers is not None:  # measured thickness: M's own layer per triangle
            cells["thickness_mm"] = on_triangles(scene.cartilage.layers.mobile.thickness_mm, np.float64)
        return Frame(s.step, s.time_s, SurfaceFrame(points, scene.mobile.triangles, {}, cells))

    def fixed_frames(self, positions: Sequence[int] | None = None) -> Sequence[Frame]:
        """The fixed body placed where each step's kinematics put it (scene axes, mm), made when read."""
        return _Frames(self._fixed_frame, self.steps if positions is None else [self.steps[k] for k in positions])

    def _fixed_frame(self, s: StepResult) -> Frame:
        fixed = self.scene.fixed
        return Frame(s.step, s.time_s, SurfaceFrame(s.fixed_placement.points(fixed.vertices_mm), fixed.triangles, {}, self.scene.fixed_cell_data()))


class _Frames(Sequence[Frame]):
    """Frames made one at a time when read: a run of many time points on a fine mesh holds one
    map in memory, not all of them."""

    def __init__(self, make: Callable[[StepResult], Frame], steps: Sequence[StepResult]) -> None:
        self._make, self._steps = make, steps

    def __len__(self) -> int:
        return len(self._steps)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self._make(s) for s in self._steps[index]]
        return self._make(self._steps[index])


def write_results(run: RunResult, out_dir: str | Path, *, frame_steps: list[int] | None = None, note: str | None = None,
                  overwrite: bool = False, provenance: Provenance | None = None, durable: bool = True,
                  time_series_only: bool = False) -> Path:
    """Write the result directory of a DEM/EDEM run (layout: :mod:`edem.resultdir`), atomically.

    Parameters
    ----------
    run : RunResult
        From :func:`edem.solver.solve`.
    out_dir : str or Path
        The directory: summary.json, timeseries.csv, pressure.pvd with one pressure_NNNN.vtp
        per time point (the mobile surface at its pose, cell data ``pressure_mpa`` in MPa,
        ``spring_length_mm``, ``in_contact``, ``ray_hit``), fixed.vtp, fixed.pvd with one
        fixed_NNNN.vtp per written time point, timeseries.sto and manifest.json listing them all.
        Written into a hidden sibling and renamed into place when complete.
    frame_steps : list of int, optional
        Positions in ``run.steps`` whose pressure maps are written (default: all).
    note : str, optional
        Recorded as the summary's "frames" entry when only some maps are written.
    overwrite : bool, optional
        Replace an existing result directory (default: refuse).
    provenance : Provenance, optional
        The resolved scene and the summary's provenance keys (:func:`edem.resultdir.provenance`),
        written in the same atomic step as the rest.
    durable : bool, optional
        Flush every file to disk before the directory is renamed into place (default). False
        for a campaign's case results, a cache verified before use (:mod:`edem.atomic_dirs`).
    time_series_only : bool, optional
        Write no surface (no pressure map, no fixed body) and no timeseries.sto, all optional in
        the format: summary.json, scene.toml, timeseries.csv and an empty pressure.pvd, for
        campaigns of hundreds of runs whose metrics read the time series only.

    Returns
    -------
    Path
        ``out_dir``.

    Raises
    ------
    SolverError
        When a value to write is not finite (naming the file and key).
    InputError
        When ``out_dir`` holds a result already (without ``overwrite``) or is not a result
        directory; ResultWriteError (an InputError) when the disk is full or not writable.
    """
    return write_run(run, out_dir, frame_steps=frame_steps, note=note, overwrite=overwrite, provenance=provenance, durable=durable,
                     time_series_only=time_series_only)
