"""The geometry stage: springs and ligaments at one pose (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs, docs/method.md#2-edem-the-time-dependent-incremental-method).

Pure functions on arrays. ``spring_geometry`` places the mobile springs at a pose, casts their
rays against the fixed body and returns lengths and candidates; ``contact_law`` turns lengths,
the cartilage and any stored (push-back) forces into the element law of the cartilage's contact
law (:mod:`edem.laws`); ``ligament_elements`` does the same for the tension-only ligaments.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np

from edem.laws import LAWS, ContactLaw, ElementLaw, LinearElements
from edem.layer_symbols import LAYER_SYMBOLS, LayerSymbol
from edem.mechanics import ShearTerms, confined_modulus_mpa, generalised_directions
from edem.raycast import RayCaster, Rays
from geometries.rowwise import add_rows, rows_times

if TYPE_CHECKING:
    from edem.thickness import Layers


@dataclass(frozen=True)
class Placement:
    """A rigid placement x = R (X - pivot) + pivot + t of a body's reference-frame points X."""

    rotation: np.ndarray  # (3, 3)
    translation_mm: np.ndarray  # (3,)
    pivot_mm: np.ndarray  # (3,)

    @staticmethod
    def identity(pivot_mm: np.ndarray | None = None) -> "Placement":
        return Placement(np.eye(3), np.zeros(3), np.zeros(3) if pivot_mm is None else np.asarray(pivot_mm, float))

    def points(self, x_mm: np.ndarray) -> np.ndarray:
        rotation, offset = self.affine()
        return add_rows(rows_times(x_mm, rotation.T), offset)

    def vectors(self, v: np.ndarray) -> np.ndarray:
        return rows_times(v, self.rotation.T)

    def affine(self) -> tuple[np.ndarray, np.ndarray]:
        """(R, b) with x = R X + b."""
        return self.rotation, self._offset_mm

    @cached_property
    def _offset_mm(self) -> np.ndarray:
        # (formed once per placement: a time point places M's and F's points several times)
        return self.pivot_mm + self.translation_mm - self.rotation @ self.pivot_mm


@dataclass(frozen=True)
class Cartilage:
    """Spring-bed material and law (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs, docs/method.md#2-edem-the-time-dependent-incremental-method, eq. 3.7-3.8)."""

    youngs_modulus_mpa: float
    poissons_ratio: float
    law: str = "threshold"  # a name of edem.laws.LAWS: threshold | gap | gap-log
    max_spring_length_mm: float = 3.5  # h_max: candidates (threshold) and ray window (all laws)
    thickness_mm: float | None = None  # undeformed combined thickness t (gap laws)
    shear_modulus_mpa: float = 0.0
    # measured thickness (edem.thickness): each side's layer; None: thickness_mm is the combined one
    layers: Layers | None = field(default=None, compare=False, repr=False)
    # the bed, a key of edem.beds.BEDS ([cartilage] coupling), and the values of its own keys (its
    # edem.beds.Bed.Keys), both read by edem.beds.read_bed
    coupling: str = field(kw_only=True)
    bed_keys: Any = field(kw_only=True)

    @property
    def confined_modulus_mpa(self) -> float:
        return confined_modulus_mpa(self.youngs_modulus_mpa, self.poissons_ratio)

    @property
    def spring_law(self) -> ContactLaw:
        """The contact law object named by ``law`` (:data:`edem.laws.LAWS`)."""
        return LAWS[self.law]

    @cached_property
    def layer_symbol(self) -> LayerSymbol:
        """The coupled layer's symbol: its key ``thin_layer_symbol`` at this Poisson's ratio
        (:data:`edem.layer_symbols.LAYER_SYMBOLS`), formed once per cartilage."""
        return LAYER_SYMBOLS[self.bed_keys.thin_layer_symbol](self.poissons_ratio)


@dataclass(frozen=True)
class SpringGeometry:
    """Springs of the mobile body at one pose: one per non-degenerate triangle (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs).

    Positions and normals at the pose are formed from M's reference ones when first asked for
    (the ray cast itself never needs them: it moves the reference rays straight into F's frame).
    """

    reference_centroid_mm: np.ndarray  # (n, 3) at M's reference pose
    reference_normal: np.ndarray  # (n, 3) unit, out of M towards F, at M's reference pose
    mobile: Placement  # M's pose
    area_mm2: np.ndarray  # (n,)
    spring_length_mm: np.ndarray  # (n,) signed ray length, +inf where no hit in the window
    candidate: np.ndarray  # (n,) bool
    # with measured thickness (cartilage.layers): the spring length above is bone to bone and this
    # is each spring's total thickness T = t_M + t_F (n,); None: the cartilage's thickness_mm
    thickness_mm: np.ndarray | None = None

    @cached_property
    def centroid_mm(self) -> np.ndarray:
        """(n, 3) spring origins at the pose."""
        return self.mobile.points(self.reference_centroid_mm)

    @cached_property
    def normal(self) -> np.ndarray:
        """(n, 3) unit spring directions at the pose."""
        return self.mobile.vectors(self.reference_normal)

    # Gathered once and shared by every stage of a step (a boolean mask over all springs costs
    # several integer gathers).
    @cached_property
    def candidate_index(self) -> np.ndarray:
        """(c,) indices of the candidate springs, ascending."""
        return self.candidate.nonzero()[0]

    @cached_property
    def candidate_length_mm(self) -> np.ndarray:
        """(c,) signed ray lengths of the candidates."""
        return self.spring_length_mm.take(self.candidate_index)

    @cached_property
    def candidate_area_mm2(self) -> np.ndarray:
        """(c,) areas of the candidates (the law, the shear springs and the pressures share them)."""
        return self.area_mm2.take(self.candidate_index)

    def candidate_thickness_mm(self, cartilage: Cartilage) -> np.ndarray | float | None:
        """The undeformed thickness the law takes: (c,) per candidate with measured thickness,
        else the cartilage's ``thickness_mm``."""
        return cartilage.thickness_mm if self.thickness_mm is None else np.take(self.thickness_mm, self.candidate_index)

    @cached_property
    def candidate_centroid_mm(self) -> np.ndarray:
        """(c, 3) origins of the candidates at the pose (without placing every spring)."""
        return self.mobile.points(np.take(self.reference_centroid_mm, self.candidate_index, axis=0))


def spring_geometry(
    centroid_mm: np.ndarray,
    normal: np.ndarray,
    area_mm2: np.ndarray,
    mobile: Placement,
    caster: RayCaster,
    fixed: Placement,
    cartilage: Cartilage,
    rays: Rays | None = None,
) -> SpringGeometry:
    """Geometry stage (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs, thesis 4.2.1): place M's springs and measure them against F.

    ``centroid_mm`` and ``normal`` are the springs at M's reference pose; ``mobile`` places M.
    Rays are cast along the springs' normals in a signed window of +-h_max (so touching or
    interpenetrating bodies still see each other), in F's own frame. Candidates: the threshold
    law takes every spring with a hit and h <= h_max (eq. 4.4); the gap laws take every spring
    with a hit in the window, and the law decides whether it is compressed. ``rays``: the same
    springs as ``caster.prepare(centroid_mm, normal)``, checked once for a run of many poses.
    """
    # F's frame seen from M's reference frame: x_F = R_f^T (R_m X + b_m - b_f) = R^T (X - t) with
    # R = R_m^T R_f and t = R_m^T (b_f - b_m), so the reference rays go to F's frame in one step.
    rotation_m, offset_m = mobile.affine()
    rotation_f, offset_f = fixed.affine()
    hits = caster.cast_rays(
        caster.prepare(centroid_mm, normal) if rays is None else rays, cartilage.max_spring_length_mm,
        rotation=rotation_m.T @ rotation_f, translation=rotation_m.T @ (offset_f - offset_m),
    )
    length = hits.spring_length_mm
    candidate = cartilage.spring_law.candidates(length, cartilage.max_spring_length_mm)
    # measured thickness: the laws see bone-to-bone lengths and per-spring thicknesses (the window
    # and the candidates stay on the ray between the scene surfaces)
    thickness = None
    if cartilage.layers is not None:
        length, thickness = cartilage.layers.along_rays(length, hits.triangle)
    return SpringGeometry(centroid_mm, normal, mobile, area_mm2, length, candidate, thickness)


def contact_law(
    geometry: SpringGeometry,
    cartilage: Cartilage,
    stored_normal_force_n: np.ndarray,
) -> ElementLaw:
    """Element law of the candidate springs under the cartilage's contact law (docs/method.md#2-edem-the-time-dependent-incremental-method, eq. 3.7
    and 3.19). ``stored_normal_force_n`` is the EDEM push-back per candidate spring (zero for DEM).
    """
    return cartilage.spring_law.elements(
        geometry.candidate_area_mm2, geometry.candidate_length_mm, cartilage.confined_modulus_mpa,
        geometry.candidate_thickness_mm(cartilage), stored_normal_force_n,
    )


def shear_terms(
    geometry: SpringGeometry,
    cartilage: Cartilage,
    reference_point_mm: np.ndarray,
    stored_tangential_force_n: np.ndarray,
) -> ShearTerms | None:
    """Shear springs k_s = G / length (eq. 3.8; the law's shear length) of the candidates, or None.

    Frictionless cartilage (G = 0) stores no tangential force: None.
    """
    if cartilage.shear_modulus_mpa == 0.0:
        return None
    sel = geometry.candidate_index
    h = cartilage.spring_law.shear_length_mm(geometry.candidate_length_mm, geometry.candidate_thickness_mm(cartilage))
    return ShearTerms(
        arm_mm=geometry.candidate_centroid_mm - reference_point_mm,
        normals=geometry.mobile.vectors(np.take(geometry.reference_normal, sel, axis=0)),
        stiffness_n_per_mm=geometry.candidate_area_mm2 * cartilage.shear_modulus_mpa / h,
        stored_force_n=stored_tangential_force_n,
    )


@dataclass(frozen=True)
class Ligament:
    """A tension-only linear spring between a point of M and a point of F (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs)."""

    name: str
    mobile_point_mm: np.ndarray
    fixed_point_mm: np.ndarray
    youngs_modulus_mpa: float
    area_mm2: float
    rest_length_mm: float

    @property
    def stiffness_n_per_mm(self) -> float:
        return self.youngs_modulus_mpa * self.area_mm2 / self.rest_length_mm


@dataclass(frozen=True)
class LigamentTable:
    """The ligaments' data as arrays, built once per run (:func:`ligament_table`)."""

    mobile_point_mm: np.ndarray  # (l, 3)
    fixed_point_mm: np.ndarray  # (l, 3)
    stiffness_n_per_mm: np.ndarray  # (l,)
    rest_length_mm: np.ndarray  # (l,)


def ligament_table(ligaments: tuple[Ligament, ...]) -> LigamentTable:
    """Stack the ligaments' points, stiffnesses and rest lengths into arrays."""
    return LigamentTable(
        np.array([lig.mobile_point_mm for lig in ligaments], float).reshape(-1, 3),
        np.array([lig.fixed_point_mm for lig in ligaments], float).reshape(-1, 3),
        np.array([lig.stiffness_n_per_mm for lig in ligaments], float),
        np.array([lig.rest_length_mm for lig in ligaments], float),
    )


def ligament_elements(
    ligaments: tuple[Ligament, ...] | LigamentTable, mobile: Placement, fixed: Placement, reference_point_mm: np.ndarray
) -> tuple[np.ndarray, LinearElements, np.ndarray]:
    """Rows g = -B^T e, law s = k (L - L0) + k delta and current lengths (mm) of the ligaments
    (given as they are, or as a :func:`ligament_table` built once for many poses).

    e is the unit vector from the ligament's point on M to its point on F; moving M by w changes
    the length by -e . w, so the tension grows with the approach delta = -e . w.
    """
    table = ligaments if isinstance(ligaments, LigamentTable) else ligament_table(ligaments)
    if not table.rest_length_mm.size:
        return np.zeros((0, 6)), LinearElements(np.zeros(0), np.zeros(0)), np.zeros(0)
    pm = mobile.points(table.mobile_point_mm)
    span = fixed.points(table.fixed_point_mm) - pm
    length = np.sqrt(np.einsum("ij,ij->i", span, span))
    e = span / length[:, None]
    k = table.stiffness_n_per_mm
    return generalised_directions(pm, -e, reference_point_mm), LinearElements(k * (length - table.rest_length_mm), k), length
