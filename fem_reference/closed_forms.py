"""Closed-form solutions used to verify the FE contact model (docs/method.md#6-the-fe-reference-and-its-discrete-twins). numpy only (no dolfinx). Units mm, N, MPa.

* Hertz line contact (plane strain) of a rigid cylinder, radius R, pressed with a load P' per
  unit length on an elastic half-space (E, nu):
  E* = E / (1 - nu^2) (rigid indenter), half-width a = sqrt(4 P' R / (pi E*)),
  peak pressure p0 = 2 P' / (pi a), p(x) = p0 sqrt(1 - x^2 / a^2).
  A thick elastic block bonded to a rigid base approaches it when its thickness and width are
  large compared with a.
* Confined compression of a thin flat slab of thickness h, lateral faces on rollers, pressed by
  d: uniform pressure p = E' d / h with the confined (oedometric) modulus
  E' = E (1 - nu) / ((1 + nu) (1 - 2 nu)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from edem.mechanics import confined_modulus_mpa


#: E' = E (1 - nu) / ((1 + nu)(1 - 2 nu)) in MPa (= lambda + 2 mu): the one definition, the spring modulus.
confined_modulus = confined_modulus_mpa


def plane_strain_modulus(youngs_modulus_mpa: float, poissons_ratio: float) -> float:
    """E* = E / (1 - nu^2): contact modulus of an elastic body against a rigid one."""
    return youngs_modulus_mpa / (1.0 - poissons_ratio**2)


@dataclass(frozen=True)
class HertzLine:
    """Hertz line contact of a rigid cylinder on an elastic half-space (plane strain)."""

    load_per_length_n_per_mm: float
    radius_mm: float
    youngs_modulus_mpa: float
    poissons_ratio: float

    @property
    def contact_modulus_mpa(self) -> float:
        return plane_strain_modulus(self.youngs_modulus_mpa, self.poissons_ratio)

    @property
    def half_width_mm(self) -> float:
        return math.sqrt(4.0 * self.load_per_length_n_per_mm * self.radius_mm
                         / (math.pi * self.contact_modulus_mpa))

    @property
    def peak_pressure_mpa(self) -> float:
        return 2.0 * self.load_per_length_n_per_mm / (math.pi * self.half_width_mm)

    def pressure_mpa(self, x_mm: np.ndarray) -> np.ndarray:
        """p(x) = p0 sqrt(1 - x^2/a^2) inside |x| < a, zero outside."""
        s = 1.0 - (np.asarray(x_mm, dtype=float) / self.half_width_mm) ** 2
        return self.peak_pressure_mpa * np.sqrt(np.clip(s, 0.0, None))

    @classmethod
    def for_half_width(cls, half_width_mm: float, radius_mm: float, youngs_modulus_mpa: float,
                       poissons_ratio: float) -> "HertzLine":
        """The load per length that gives half-width ``half_width_mm``: P' = pi a^2 E* / (4 R)."""
        es = plane_strain_modulus(youngs_modulus_mpa, poissons_ratio)
        p = math.pi * half_width_mm**2 * es / (4.0 * radius_mm)
        return cls(p, radius_mm, youngs_modulus_mpa, poissons_ratio)


def hertz_line_contact(load_per_length_n_per_mm: float, radius_mm: float, youngs_modulus_mpa: float,
                       poissons_ratio: float) -> tuple[float, float]:
    """(half-width a in mm, peak pressure p0 in MPa) of Hertz line contact, rigid cylinder."""
    h = HertzLine(load_per_length_n_per_mm, radius_mm, youngs_modulus_mpa, poissons_ratio)
    return h.half_width_mm, h.peak_pressure_mpa


def confined_compression_pressure(youngs_modulus_mpa: float, poissons_ratio: float,
                                  thickness_mm: float, displacement_mm: float) -> float:
    """p = E' d / h (MPa) for a laterally confined slab of thickness h compressed by d."""
    return confined_modulus(youngs_modulus_mpa, poissons_ratio) * displacement_mm / thickness_mm


def confined_compression_displacement(youngs_modulus_mpa: float, poissons_ratio: float,
                                      thickness_mm: float, pressure_mpa: float) -> float:
    """d = p h / E' (mm)."""
    return pressure_mpa * thickness_mm / confined_modulus(youngs_modulus_mpa, poissons_ratio)


def fit_elliptic_half_width(x_mm: np.ndarray, p_mpa: np.ndarray, *,
                            min_fraction: float = 0.2) -> tuple[float, float]:
    """Fit p^2 = p0^2 (1 - x^2 / a^2) (Hertz profile) by least squares on the points with
    p > min_fraction * max p; return (a, p0). A half-width estimate that does not depend on
    how the contact edge falls between mesh points."""
    x = np.abs(np.asarray(x_mm, dtype=float))
    p = np.asarray(p_mpa, dtype=float)
    m = p > min_fraction * p.max()
    if m.sum() < 3:
        raise ValueError("too few points in contact to fit a Hertz profile")
    A = np.column_stack([np.ones(m.sum()), x[m] ** 2])
    c0, c1 = np.linalg.lstsq(A, p[m] ** 2, rcond=None)[0]
    if c0 <= 0 or c1 >= 0:
        raise ValueError("pressure profile is not Hertz-like (p^2 not decreasing in x^2)")
    return math.sqrt(-c0 / c1), math.sqrt(c0)


def observed_order(values: np.ndarray, refinement_ratio: float = 2.0) -> float:
    """Observed convergence order from three solutions on meshes refined by a constant ratio:
    p = log(|f1 - f2| / |f2 - f3|) / log(r) (f1 coarsest)."""
    f1, f2, f3 = (float(v) for v in values)
    d12, d23 = abs(f1 - f2), abs(f2 - f3)
    if d23 == 0.0:
        return math.inf
    return math.log(d12 / d23) / math.log(refinement_ratio)


def observed_order_vs_exact(errors: np.ndarray, refinement_ratio: float = 2.0) -> np.ndarray:
    """Orders between successive meshes from errors against an exact value."""
    e = np.abs(np.asarray(errors, dtype=float))
    return np.log(e[:-1] / e[1:]) / math.log(refinement_ratio)


def richardson_extrapolate(values: np.ndarray, refinement_ratio: float = 2.0) -> float:
    """Extrapolated limit from the two finest of three solutions using the observed order."""
    p = observed_order(values, refinement_ratio)
    f2, f3 = float(values[1]), float(values[2])
    if not math.isfinite(p) or p <= 0:
        return f3
    return f3 + (f3 - f2) / (refinement_ratio**p - 1.0)


def kelvin_voigt_creep(time_s: np.ndarray, load_times_s: np.ndarray, load_values: np.ndarray,
                       relaxation_time_s: float) -> np.ndarray:
    """Exact solution of tau du/dt + u = r(t), u(t_0) = 0, for r piecewise linear through
    (load_times_s, load_values) (constant after the last point), at ``time_s``.

    Superposition: the jump r(t_0) at t_0 responds with r_0 (1 - exp(-s / tau)) and each change
    of slope m at t_i with m (s - tau (1 - exp(-s / tau))), s = t - t_i >= 0. In confined
    compression of a Kelvin-Voigt slab of thickness h under pressure p(t), r = p h / E' and u
    is the plate's displacement: a step's creep u = r (1 - exp(-t/tau)), a ramp's
    (r/T) (t - tau (1 - exp(-t/tau))), and after unloading at t_1 the recovery
    u(t_1) exp(-(t - t_1)/tau).
    """
    t = np.asarray(time_s, dtype=float)
    tb = np.asarray(load_times_s, dtype=float)
    r = np.asarray(load_values, dtype=float)
    tau = float(relaxation_time_s)
    slopes = np.append(np.diff(r) / np.diff(tb), 0.0)
    changes = np.diff(np.concatenate([[0.0], slopes]))

    def ramp(s: np.ndarray) -> np.ndarray:
        s = np.clip(s, 0.0, None)
        return s + tau * np.expm1(-s / tau)

    u = r[0] * -np.expm1(-np.clip(t - tb[0], 0.0, None) / tau)
    for ti, m in zip(tb, changes):
        u = u + m * ramp(t - ti)
    return u
