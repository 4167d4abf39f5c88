"""Contact laws of the spring bed: one class per law, registered in :data:`LAWS` (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs, docs/method.md#2-edem-the-time-dependent-incremental-method).

A contact law says, for the springs of the mobile body (area A, ray length h, confined modulus
E' of eq. 3.7, undeformed thickness t where the law has one):

* which springs with a ray hit are candidates (:meth:`ContactLaw.candidates`) and how far the
  rays look by default (:meth:`ContactLaw.default_window_mm`);
* the scalar element law s(delta) of the candidates, with its energy (:meth:`ContactLaw.elements`,
  returning :class:`LinearElements` or :class:`LogElements`);
* the length the shear springs k_s = G / length use (:meth:`ContactLaw.shear_length_mm`);
* the strain, compression over undeformed length (:meth:`ContactLaw.strain`);
* its FE twin: the name of the FE model of :mod:`fem_reference.models` that is its continuum.

Element laws map the approach delta of every element (mm, along its generalised direction) to
its force s (N, compression > 0) and stiffness ds/ddelta (N/mm); the energy phi has
phi' = max(s, 0). :func:`stack_elements` joins the element laws of the springs and ligaments so
the solver sees one law over all its elements.

To add a law: one subclass of :class:`ContactLaw` here, added to :data:`LAWS`, plus its tests.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import cached_property
from typing import ClassVar

import numpy as np

# --------------------------------------------------------------------------------------------
# element laws: s(delta) of a set of unilateral elements, vectorised


@dataclass(frozen=True)
class LinearElements:
    """s = s0 + c delta per element (the threshold law with the EDEM push-back in s0, the
    linear gap law with s0 = A E' (t - h) / t, ligaments)."""

    offset_n: np.ndarray  # (m,) s0 in N
    stiffness_n_per_mm: np.ndarray  # (m,) c in N/mm

    def __len__(self) -> int:
        return int(self.offset_n.shape[0])

    def force_and_stiffness(self, approach_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(s, ds/ddelta) at the approaches (m,); ds/ddelta is the law's own array (read only)."""
        return self.offset_n + self.stiffness_n_per_mm * approach_mm, self.stiffness_n_per_mm

    @cached_property
    def _twice_stiffness(self) -> np.ndarray:
        return 2.0 * self.stiffness_n_per_mm

    def energy(self, approach_mm: np.ndarray) -> np.ndarray:
        """phi with phi' = max(s, 0): max(s, 0)^2 / (2 c)."""
        return self.force_stiffness_energy(approach_mm)[2]

    def force_stiffness_energy(self, approach_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`force_and_stiffness` and :meth:`energy` at the same approaches, sharing s
        (a solve evaluates both at every line-search trial)."""
        force = self.offset_n + self.stiffness_n_per_mm * approach_mm
        phi = np.maximum(force, 0.0)  # then in place on this one new array
        np.square(phi, out=phi)
        phi /= self._twice_stiffness
        return force, self.stiffness_n_per_mm, phi

    def max_approach_mm(self) -> np.ndarray:
        """Largest admissible approach: unbounded."""
        return np.full(len(self), np.inf)


@dataclass(frozen=True)
class LogElements:
    """The logarithmic law (Blankevoort): with compression d = d0 + delta and a = c t = A E',
    s = -a ln(1 - d / t) for d > 0 and its linear extension s = c d for d <= 0."""

    compression_mm: np.ndarray  # (m,) d0 in mm
    stiffness_n_per_mm: np.ndarray  # (m,) c, the stiffness at d = 0
    thickness_mm: np.ndarray  # (m,) t > 0

    def __len__(self) -> int:
        return int(self.compression_mm.shape[0])

    def _parts(self, approach_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        d = self.compression_mm + approach_mm
        compressed = d > 0
        return d, compressed, np.where(compressed, d / self.thickness_mm, 0.0)

    def force_and_stiffness(self, approach_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(s, ds/ddelta) at the approaches (m,); +inf once compressed past t."""
        c = self.stiffness_n_per_mm
        d, compressed, ratio = self._parts(approach_mm)
        force = c * d
        stiffness = c.copy()
        if np.any(compressed):
            inside = np.minimum(ratio[compressed], 1.0)
            t = self.thickness_mm[compressed]
            with np.errstate(divide="ignore"):
                force[compressed] = -c[compressed] * t * np.log1p(-inside)
                stiffness[compressed] = c[compressed] / (1.0 - inside)
        return force, stiffness

    def energy(self, approach_mm: np.ndarray) -> np.ndarray:
        """phi with phi' = max(s, 0); +inf where an element is compressed past t."""
        c = self.stiffness_n_per_mm
        _, compressed, ratio = self._parts(approach_mm)
        out = np.zeros(len(self))
        if np.any(compressed):
            inside = ratio[compressed]
            t = self.thickness_mm[compressed]
            with np.errstate(divide="ignore", invalid="ignore"):
                e = c[compressed] * t * t * ((1.0 - inside) * np.log1p(-np.minimum(inside, 1.0)) + inside)
            out[compressed] = np.where(inside < 1.0, e, np.inf)
        return out

    def force_stiffness_energy(self, approach_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`force_and_stiffness` and :meth:`energy` at the same approaches."""
        return *self.force_and_stiffness(approach_mm), self.energy(approach_mm)

    def max_approach_mm(self) -> np.ndarray:
        """Largest admissible approach: an element cannot be compressed past its thickness."""
        return self.thickness_mm - self.compression_mm


@dataclass(frozen=True)
class StackedElements:
    """Element laws one after the other (contact springs, then ligaments): one law over all."""

    parts: tuple[LinearElements | LogElements | StackedElements, ...]

    def __len__(self) -> int:
        return sum(len(p) for p in self.parts)

    def _split(self, approach_mm: np.ndarray) -> list[np.ndarray]:
        # Plain slices: np.split's generic machinery costs more than the laws themselves here.
        out, start = [], 0
        for part in self.parts:
            stop = start + len(part)
            out.append(approach_mm[start:stop])
            start = stop
        return out

    def force_and_stiffness(self, approach_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        pairs = [p.force_and_stiffness(a) for p, a in zip(self.parts, self._split(approach_mm))]
        return np.concatenate([f for f, _ in pairs]), np.concatenate([k for _, k in pairs])

    def energy(self, approach_mm: np.ndarray) -> np.ndarray:
        return np.concatenate([p.energy(a) for p, a in zip(self.parts, self._split(approach_mm))])

    def force_stiffness_energy(self, approach_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`force_and_stiffness` and :meth:`energy` at the same approaches."""
        triples = [p.force_stiffness_energy(a) for p, a in zip(self.parts, self._split(approach_mm))]
        return tuple(np.concatenate([t[i] for t in triples]) for i in range(3))

    def max_approach_mm(self) -> np.ndarray:
        return np.concatenate([p.max_approach_mm() for p in self.parts])


ElementLaw = LinearElements | LogElements | StackedElements


def stack_elements(*laws: ElementLaw) -> ElementLaw:
    """One element law over the elements of ``laws``, in order (a single law is returned as is;
    linear laws only, e.g. threshold springs and ligaments, are joined into one linear law, which
    the solver then evaluates without splitting its approaches per part)."""
    kept = tuple(law for law in laws if len(law)) or laws[:1]
    if len(kept) == 1:
        return kept[0]
    if all(isinstance(law, LinearElements) for law in kept):
        return LinearElements(
            np.concatenate([law.offset_n for law in kept]), np.concatenate([law.stiffness_n_per_mm for law in kept])
        )
    return StackedElements(kept)


# --------------------------------------------------------------------------------------------
# contact laws


def _thickness(thickness_mm: float | np.ndarray) -> float | np.ndarray:
    """t as given: one thickness (float) or one per candidate (measured thickness, edem.thickness)."""
    return float(thickness_mm) if np.ndim(thickness_mm) == 0 else np.asarray(thickness_mm, dtype=float)


class ContactLaw(ABC):
    """A spring-bed contact law. Subclasses set the class attributes and the methods below.

    Arrays are per candidate spring: ``area_mm2`` A, ``spring_length_mm`` h (signed ray length),
    ``approach_mm`` delta; ``thickness_mm`` is the undeformed combined thickness t (None for
    laws without one), one value or one per candidate (measured thickness: then h is the
    bone-to-bone length, docs/method.md#measured-cartilage-thickness).
    """

    name: ClassVar[str]
    #: whether the law needs cartilage.thickness_mm
    needs_thickness: ClassVar[bool] = False
    #: whether h <= 0 (interpenetrating bodies) leaves the law without meaning
    needs_positive_length: ClassVar[bool] = True
    #: name of the FE model (fem_reference.models) that is this law's continuum twin
    fe_twin: ClassVar[str]
    #: under ``coupling = "thin-layer"`` (edem.thin_layer_contact), what the element offset s0 is:
    #: "carried" (a force carried into the step, the EDEM push-back: the layer starts deflected by
    #: C s0) or "overlap" (geometric: the layer must be compressed by t - h); None: cannot couple
    thin_layer: ClassVar[str | None] = None
    #: under the coupling, where the layer is: "surface" (bonded to all of M, going on beyond the
    #: candidates, as the FE layer does) or "candidates" (the cartilage fills the gap only where
    #: the springs are candidates, as the FE slab does: the layer ends at their boundary with a
    #: free lateral face, where it can squeeze out)
    thin_layer_extent: ClassVar[str] = "surface"
    #: whether s(delta) is nonlinear: the coupled layer then linearises its columns at each
    #: iteration (:meth:`column_excess_mm`)
    nonlinear: ClassVar[bool] = False

    @abstractmethod
    def default_window_mm(self, thickness_mm: float | None) -> float:
        """h_max when the scene gives none (mm)."""
        ...

    def candidates(self, spring_length_mm: np.ndarray, window_mm: float) -> np.ndarray:
        """(n,) bool: which springs with a finite ray length take part (eq. 4.4 for the threshold law)."""
        return np.isfinite(spring_length_mm)

    @abstractmethod
    def elements(self, area_mm2: np.ndarray, spring_length_mm: np.ndarray, confined_modulus_mpa: float,
                 thickness_mm: float | None, stored_normal_force_n: np.ndarray) -> ElementLaw:
        """The element law s(delta) of the candidates (N); ``stored_normal_force_n`` is the EDEM
        push-back per candidate (zero for DEM)."""
        ...

    def column_excess_mm(
        self, force_n: np.ndarray, area_mm2: np.ndarray, confined_modulus_mpa: float, thickness_mm: float | None
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Under the coupling, a nonlinear law's column: how much more than the linear t f / (A E')
        a column deflects (mm) under its force f (N) when its neighbours carry the same pressure,
        and the derivative (mm/N); arrays (m,). None for a linear law (the default)."""
        return None

    @abstractmethod
    def shear_length_mm(self, spring_length_mm: np.ndarray, thickness_mm: float | None) -> np.ndarray:
        """Length of the shear springs k_s = G / length (eq. 3.8), mm."""
        ...

    @abstractmethod
    def strain(self, spring_length_mm: np.ndarray, approach_mm: np.ndarray, thickness_mm: float | None) -> np.ndarray:
        """Compression over undeformed length after an approach (dimensionless)."""
        ...


class ThresholdLaw(ContactLaw):
    """Linear springs of the current length h, candidates h <= h_max: s = s_stored + A E' / h delta
    (incremental: the stiffness follows the current h; eq. 3.7). With measured thickness h is the
    bone-to-bone length, so k = A E' / (t_M + t_F) where the articular surfaces touch; the
    candidates stay those within h_max along the ray."""

    name = "threshold"
    fe_twin = "slab"
    thin_layer = "carried"
    thin_layer_extent = "candidates"

    def default_window_mm(self, thickness_mm: float | None) -> float:
        return 3.5

    def candidates(self, spring_length_mm: np.ndarray, window_mm: float) -> np.ndarray:
        return np.isfinite(spring_length_mm) & (spring_length_mm <= window_mm)

    def elements(self, area_mm2, spring_length_mm, confined_modulus_mpa, thickness_mm, stored_normal_force_n):
        return LinearElements(np.asarray(stored_normal_force_n, float), area_mm2 * confined_modulus_mpa / spring_length_mm)

    def shear_length_mm(self, spring_length_mm, thickness_mm):
        return spring_length_mm

    def strain(self, spring_length_mm, approach_mm, thickness_mm):
        return approach_mm / spring_length_mm


class GapLaw(ContactLaw):
    """Linear springs of the undeformed thickness t: s = A E' (t - h + delta) / t (eq. 3.19)."""

    name = "gap"
    needs_thickness = True
    needs_positive_length = False
    fe_twin = "layer"
    thin_layer = "overlap"

    def default_window_mm(self, thickness_mm: float | None) -> float:
        return 2.0 * float(thickness_mm)

    def elements(self, area_mm2, spring_length_mm, confined_modulus_mpa, thickness_mm, stored_normal_force_n):
        t = _thickness(thickness_mm)
        return LinearElements(area_mm2 * confined_modulus_mpa * (t - spring_length_mm) / t, area_mm2 * confined_modulus_mpa / t)

    def shear_length_mm(self, spring_length_mm, thickness_mm):
        return np.full(spring_length_mm.shape, _thickness(thickness_mm))

    def strain(self, spring_length_mm, approach_mm, thickness_mm):
        t = _thickness(thickness_mm)
        return (t - spring_length_mm + approach_mm) / t


class GapLogLaw(GapLaw):
    """Blankevoort's logarithmic springs: s = -A E' ln(1 - (t - h + delta) / t), which stiffens
    without bound as the compression approaches t."""

    name = "gap-log"
    needs_positive_length = True
    nonlinear = True

    def elements(self, area_mm2, spring_length_mm, confined_modulus_mpa, thickness_mm, stored_normal_force_n):
        t = _thickness(thickness_mm)
        return LogElements(t - spring_length_mm, area_mm2 * confined_modulus_mpa / t, np.full(spring_length_mm.shape, t))

    def column_excess_mm(self, force_n, area_mm2, confined_modulus_mpa, thickness_mm):
        """The law inverted, d = t (1 - exp(-x)) with x = f / (A E') (its linear extension for
        f <= 0), minus t x: -t (x + expm1(-x)) <= 0, derivative t expm1(-x) / (A E')."""
        t = _thickness(thickness_mm)
        per_n = 1.0 / (area_mm2 * confined_modulus_mpa)
        x = np.maximum(force_n, 0.0) * per_n
        return -t * (x + np.expm1(-x)), t * np.expm1(-x) * per_n


#: every contact law by name (the scene's ``cartilage.law``)
LAWS: dict[str, ContactLaw] = {law.name: law for law in (ThresholdLaw(), GapLaw(), GapLogLaw())}
