"""Closed-form solutions used to verify the FE contact model (docs/method.md#6-the-fe-reference-and-its-discrete-twins). numpy and scipy only (no dolfinx). Units mm, N, MPa, s.

* Hertz line contact (plane strain) of a rigid cylinder, radius R, pressed with a load P' per
  unit length on an elastic half-space (E, nu):
  E* = E / (1 - nu^2) (rigid indenter), half-width a = sqrt(4 P' R / (pi E*)),
  peak pressure p0 = 2 P' / (pi a), p(x) = p0 sqrt(1 - x^2 / a^2).
  A thick elastic block bonded to a rigid base approaches it when its thickness and width are
  large compared with a. Two elastic cylinders (the second: R2, E2, nu2): the same with
  1 / E* = (1 - nu^2) / E + (1 - nu2^2) / E2 and 1 / R* = 1 / R + 1 / R2 in place of E* and R
  (two equal cylinders: E* = E / (2 (1 - nu^2)), R* = R / 2).
* Confined compression of a thin flat slab of thickness h, lateral faces on rollers, pressed by
  d: uniform pressure p = E' d / h with the confined (oedometric) modulus
  E' = E (1 - nu) / ((1 + nu) (1 - 2 nu)).
* Kelvin-Voigt creep of that slab under a piecewise-linear load (:func:`kelvin_voigt_creep`).
* Biphasic confined compression (Mow et al. 1980): creep under a step stress and stress
  relaxation under a ramp-and-hold displacement, series summed to a stated tolerance
  (:func:`biphasic_confined_creep`, :func:`biphasic_confined_relaxation`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from edem.mechanics import confined_modulus_mpa


#: E' = E (1 - nu) / ((1 + nu)(1 - 2 nu)) in MPa (= lambda + 2 mu): the one definition, the spring modulus.
confined_modulus = confined_modulus_mpa


def plane_strain_modulus(youngs_modulus_mpa: float, poissons_ratio: float) -> float:
    """E* = E / (1 - nu^2): contact modulus of an elastic body against a rigid one."""
    return youngs_modulus_mpa / (1.0 - poissons_ratio**2)


@dataclass(frozen=True)
class HertzLine:
    """Hertz line contact of a rigid cylinder on an elastic half-space (plane strain); with a
    second body's ``other_*`` (default: rigid, flat), of two elastic cylinders."""

    load_per_length_n_per_mm: float
    radius_mm: float
    youngs_modulus_mpa: float
    poissons_ratio: float
    other_radius_mm: float = math.inf
    other_youngs_modulus_mpa: float = math.inf
    other_poissons_ratio: float = 0.0

    @property
    def contact_modulus_mpa(self) -> float:
        """E* = 1 / ((1 - nu^2) / E + (1 - nu2^2) / E2)."""
        compliance = 1.0 / plane_strain_modulus(self.youngs_modulus_mpa, self.poissons_ratio)
        if math.isfinite(self.other_youngs_modulus_mpa):
            compliance += 1.0 / plane_strain_modulus(self.other_youngs_modulus_mpa, self.other_poissons_ratio)
        return 1.0 / compliance

    @property
    def effective_radius_mm(self) -> float:
        """R* = 1 / (1 / R + 1 / R2)."""
        return 1.0 / (1.0 / self.radius_mm + 1.0 / self.other_radius_mm)

    @property
    def half_width_mm(self) -> float:
        return math.sqrt(4.0 * self.load_per_length_n_per_mm * self.effective_radius_mm
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
                       poissons_ratio: float, **other: float) -> "HertzLine":
        """The load per length that gives half-width ``half_width_mm``: P' = pi a^2 E* / (4 R*)
        (``other``: the second cylinder's ``other_radius_mm``, ``other_youngs_modulus_mpa``,
        ``other_poissons_ratio``)."""
        unit = cls(1.0, radius_mm, youngs_modulus_mpa, poissons_ratio, **other)
        p = math.pi * half_width_mm**2 * unit.contact_modulus_mpa / (4.0 * unit.effective_radius_mm)
        return cls(p, radius_mm, youngs_modulus_mpa, poissons_ratio, **other)


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


# --------------------------------------------------------------------------------------------
# Biphasic confined compression (Mow et al. 1980; docs/method.md#the-biphasic-anchor)
# --------------------------------------------------------------------------------------------
#
# A layer 0 < z < h in a confining chamber: impermeable and fixed at z = 0, loaded at z = h
# through a free-draining porous platen (p = 0). Equilibrium d/dz (H_A du/dz - p) = 0 makes the
# total stress sigma(t) = H_A du/dz - p uniform in z; mass conservation d/dt (du/dz) =
# d/dz (k dp/dz) then turns into the diffusion equation du/dt = c d2u/dz2 with c = H_A k (mm^2/s)
# for the displacement (integrated once in z; u(0) = 0 and dp/dz(0) = 0 fix the constant), and
# the consolidation time T = h^2 / (H_A k). Below s = t / T is the dimensionless time.
#
# Each closed form is a Fourier series for s >= BIPHASIC_SHORT_TIME, summed until a bound on its
# tail falls below ``tol`` (absolute, on the dimensionless value; at most about 60 terms), and
# below it the leading term of the same solution's image series (by reflections in z = 0 and
# z = h), whose next terms are below erfc(1 / (2 sqrt(1e-3))) < 1e-100 there.

#: the default truncation of the biphasic series: tail below 1e-12 of their equilibrium values
BIPHASIC_SERIES_TOLERANCE = 1e-12
#: below this t / T the closed forms take their short-time (image) form
BIPHASIC_SHORT_TIME = 1e-3


def consolidation_time_s(thickness_mm: float, aggregate_modulus_mpa: float,
                         permeability_mm4_per_n_s: float) -> float:
    """T = h^2 / (H_A k) in s, the time scale of confined consolidation (mm^2 / (MPa mm^4/(N s)))."""
    return thickness_mm**2 / (aggregate_modulus_mpa * permeability_mm4_per_n_s)


def _fourier(term, tail_bound, s: np.ndarray, tol: float) -> np.ndarray:
    """sum_{n >= 0} term(n, s) at s >= BIPHASIC_SHORT_TIME, stopped at the first N whose
    ``tail_bound(N, s)`` (a bound on sum_{n >= N} |term(n, s)|, N >= 1) is below ``tol``."""
    s = np.maximum(s, BIPHASIC_SHORT_TIME)
    total, n = term(0, s), 1
    while np.any(tail_bound(n, s) > tol):
        total, n = total + term(n, s), n + 1
    return total


def _lam(n: int) -> float:
    return (n + 0.5) * math.pi


def _dimensionless_time(time_s: Any, consolidation_s: float) -> np.ndarray:
    s = np.asarray(time_s, dtype=float) / consolidation_s
    if np.any(s < 0.0) or not np.all(np.isfinite(s)):
        raise ValueError("biphasic closed forms need finite times t >= 0")
    return s


def biphasic_creep_fraction(s: Any, tol: float = BIPHASIC_SERIES_TOLERANCE) -> np.ndarray:
    """u(h, t) / u_inf of confined creep under a step stress, at s = t / T:

        1 - sum_{n >= 0} 2 / lambda_n^2 exp(-lambda_n^2 s),   lambda_n = (n + 1/2) pi;
        2 sqrt(s / pi) for s < BIPHASIC_SHORT_TIME.

    Derivation: with the step sigma = -sigma0 the strain e = du/dz diffuses (de/dt = c d2e/dz2)
    from e = 0 at t = 0+ (the undrained instant: no volume change) to e(h) = -sigma0 / H_A (p = 0
    at the platen), de/dz(0) = 0 (no flux at the bottom); its cosine series integrated over
    0 < z < h gives the above (sum 2 / lambda_n^2 = 1: no displacement at t = 0+). Tail bound
    after N terms: 2 exp(-lambda_N^2 s) / (pi^2 N), since sum_{n >= N} (n + 1/2)^-2 <= 1 / N.
    The image series is 2 sqrt(s) (pi^-1/2 + 2 sum_{m >= 1} (-1)^m ierfc(m / sqrt(s))).
    """
    s = np.asarray(s, dtype=float)
    series = _fourier(lambda n, x: 2.0 / _lam(n)**2 * np.exp(-_lam(n)**2 * x),
                      lambda n, x: 2.0 * np.exp(-_lam(n)**2 * x) / (math.pi**2 * n), s, tol)
    return np.where(s < BIPHASIC_SHORT_TIME, 2.0 * np.sqrt(s / math.pi), 1.0 - series)


def biphasic_creep_pressure_fraction(s: Any, height_fraction: float = 0.0,
                                     tol: float = BIPHASIC_SERIES_TOLERANCE) -> np.ndarray:
    """p(z, t) / sigma0 of confined creep under a step stress sigma0, at z = ``height_fraction`` h
    (0: the impermeable bottom, 1: the platen) and s = t / T:

        sum_{n >= 0} 2 (-1)^n / lambda_n cos(lambda_n z / h) exp(-lambda_n^2 s);
        1 - erfc((1 - z/h) / (2 sqrt(s))) - erfc((1 + z/h) / (2 sqrt(s))) for s < BIPHASIC_SHORT_TIME

    (p = H_A e + sigma0 with the strain series of :func:`biphasic_creep_fraction`); 1 at t = 0+
    below the platen (the fluid carries the whole load), 0 at the platen. Tail bound after N
    terms: the N-th term's bound 2 / lambda_N exp(-lambda_N^2 s) over 1 - exp(-2 pi^2 (N + 1) s),
    a geometric bound on the ratio of successive terms.
    """
    from scipy.special import erfc

    s = np.asarray(s, dtype=float)
    zeta = float(height_fraction)
    if not 0.0 <= zeta <= 1.0:
        raise ValueError(f"height_fraction must lie in [0, 1], got {height_fraction!r}")
    if zeta == 1.0:
        return np.zeros_like(s)
    series = _fourier(lambda n, x: 2.0 * (-1) ** n / _lam(n) * math.cos(_lam(n) * zeta) * np.exp(-_lam(n)**2 * x),
                      lambda n, x: 2.0 / _lam(n) * np.exp(-_lam(n)**2 * x) / -np.expm1(-2.0 * math.pi**2 * (n + 1) * x),
                      s, tol)
    r = 2.0 * np.sqrt(np.clip(s, 1e-300, BIPHASIC_SHORT_TIME))
    return np.where(s < BIPHASIC_SHORT_TIME, 1.0 - erfc((1.0 - zeta) / r) - erfc((1.0 + zeta) / r), series)


def _ramp_response(x: np.ndarray, tol: float) -> np.ndarray:
    """F(x) = x + 1/3 - (2 / pi^2) sum_{m >= 1} exp(-m^2 pi^2 x) / m^2 (F(0) = 0; tail bound after
    M terms exp(-(M + 1)^2 pi^2 x) / M); 2 sqrt(x / pi) for x < BIPHASIC_SHORT_TIME (image series
    2 sqrt(x) (pi^-1/2 + 2 sum_{j >= 1} ierfc(j / sqrt(x))))."""
    series = _fourier(lambda n, y: np.exp(-(n + 1)**2 * math.pi**2 * y) / (n + 1)**2,
                      lambda n, y: np.exp(-(n + 1)**2 * math.pi**2 * y) / n, x, tol)
    return np.where(x < BIPHASIC_SHORT_TIME, 2.0 * np.sqrt(x / math.pi),
                    x + 1.0 / 3.0 - 2.0 / math.pi**2 * series)


def biphasic_ramp_relaxation_fraction(s: Any, ramp_s: float,
                                      tol: float = BIPHASIC_SERIES_TOLERANCE) -> np.ndarray:
    """sigma(t) / sigma_inf of confined stress relaxation under a ramp-and-hold displacement
    (compression d0 reached linearly at t0, held after), at s = t / T, s0 = t0 / T; sigma_inf =
    H_A d0 / h is the drained equilibrium:

        sigma / sigma_inf = F(s) / s0                 for s <= s0,
                            (F(s) - F(s - s0)) / s0   for s >= s0,
        F(s) = s + 1/3 - (2 / pi^2) sum_{m >= 1} exp(-m^2 pi^2 s) / m^2    (F(0) = 0).

    Derivation: u solves du/dt = c d2u/dz2 with u(0, t) = 0, u(h, t) = -d(t), u(z, 0) = 0. A unit
    step of the platen's displacement gives u = z / h - sum_m 2 (-1)^(m+1) / (m pi)
    sin(m pi z / h) exp(-m^2 pi^2 s), whose platen stress H_A du/dz(h) (p = 0 there) is
    (H_A / h) (1 + 2 sum_m exp(-m^2 pi^2 s)); Duhamel's integral of it against the ramp's rate
    d0 / t0 is F, and the hold is the ramp minus the same ramp delayed by t0. During a slow ramp
    the stress leads the drained one by H_A (d0 / t0) T / (3 h) (the 1/3).
    """
    s = np.asarray(s, dtype=float)
    s0 = float(ramp_s)
    if not s0 > 0.0:
        raise ValueError(f"the ramp's duration must be > 0, got {ramp_s!r}")
    held = _ramp_response(s, tol) - _ramp_response(np.clip(s - s0, 0.0, None), tol)
    return np.where(s <= s0, _ramp_response(np.minimum(s, s0), tol), held) / s0


def biphasic_confined_creep(time_s: Any, thickness_mm: float, aggregate_modulus_mpa: float,
                            permeability_mm4_per_n_s: float, stress_mpa: float,
                            tol: float = BIPHASIC_SERIES_TOLERANCE) -> tuple[np.ndarray, np.ndarray]:
    """Confined creep under a step stress sigma0 = ``stress_mpa`` applied at t = 0 (Mow et al.
    1980): (the platen's displacement into the layer in mm, the pressure at the impermeable
    bottom in MPa) at ``time_s`` (n,); u -> sigma0 h / H_A, p -> 0 at equilibrium."""
    s = _dimensionless_time(time_s, consolidation_time_s(thickness_mm, aggregate_modulus_mpa,
                                                         permeability_mm4_per_n_s))
    u_inf = stress_mpa * thickness_mm / aggregate_modulus_mpa
    return u_inf * biphasic_creep_fraction(s, tol), stress_mpa * biphasic_creep_pressure_fraction(s, 0.0, tol)


def biphasic_confined_relaxation(time_s: Any, thickness_mm: float, aggregate_modulus_mpa: float,
                                 permeability_mm4_per_n_s: float, displacement_mm: float, ramp_time_s: float,
                                 tol: float = BIPHASIC_SERIES_TOLERANCE) -> np.ndarray:
    """Confined stress relaxation (Mow et al. 1980): the compressive stress on the platen in MPa
    at ``time_s`` (n,) when the platen moves ``displacement_mm`` into the layer linearly over
    ``ramp_time_s`` and holds; -> H_A d0 / h at equilibrium."""
    T = consolidation_time_s(thickness_mm, aggregate_modulus_mpa, permeability_mm4_per_n_s)
    s = _dimensionless_time(time_s, T)
    sigma_inf = aggregate_modulus_mpa * displacement_mm / thickness_mm
    return sigma_inf * biphasic_ramp_relaxation_fraction(s, ramp_time_s / T, tol)
