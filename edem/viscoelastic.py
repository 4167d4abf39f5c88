"""Kelvin-Voigt springs in EDEM: H du/dt + K u = T - p with H = tau K (docs/method.md#4-viscoelastic-edem-thesis-chapter-6, thesis eq. 6.13-6.18).

Within one step (t_{k-1} -> t_k, geometry and active set frozen) the load is linear in time,
T(s) = T_{k-1} + (T_k - T_{k-1}) s / dt, so with r(s) = K^-1 (T(s) - p) the increment obeys
tau du/ds + u = r(s), u(0) = 0. Every integrator here returns

    u(dt) = phi K^-1 (T_{k-1} - p) + psi K^-1 (T_k - T_{k-1})

with weights (phi, psi) that depend only on z = dt / tau:
- exact: phi = 1 - exp(-z), psi = 1 - phi / z (the closed form of the linear ODE: unconditionally
  stable and exact for loads piecewise linear in time);
- rk2 (the thesis's Heun step): phi = z - z^2 / 2, psi = z / 2; its creep amplification
  1 - z + z^2 / 2 exceeds 1 in modulus for z > 2, i.e. dt > 2 tau.
Since the dashpots carry T - (p + K u) at the end of the step, the total spring force (elastic +
viscous) equals the quasi-static elastic solution under T_k: pressure follows the load (docs/method.md#4-viscoelastic-edem-thesis-chapter-6).
"""

from __future__ import annotations

import math

import numpy as np

from geometries.errors import InputError


RK2_STABILITY_LIMIT = 2.0  # dt / tau


def integrator_weights(dt_s: float, relaxation_time_s: float, integrator: str) -> tuple[float, float]:
    """(phi, psi) of one step of length dt for the exact or RK2 integrator (module docstring)."""
    if dt_s <= 0.0:
        return 0.0, 0.0  # no time elapses: a step load is carried by the dashpots alone
    z = dt_s / relaxation_time_s
    if integrator == "exact":
        phi = -math.expm1(-z)
        # psi = 1 - (1 - exp(-z)) / z, written to keep its accuracy for small z.
        psi = 1.0 - phi / z if z > 1e-4 else z / 2.0 - z * z / 6.0 + z**3 / 24.0
        return phi, psi
    if integrator == "rk2":
        return z - 0.5 * z * z, 0.5 * z
    raise ValueError(f"unknown integrator {integrator!r}")


def check_rk2_stability(time_s, relaxation_time_s: float, allow_unstable: bool, file: str | None = None) -> list[str]:
    """Refuse RK2 beyond dt > 2 tau (or warn when the scene insists), docs/method.md#4-viscoelastic-edem-thesis-chapter-6."""
    dt = float(np.max(np.diff(time_s), initial=0.0))
    if dt <= RK2_STABILITY_LIMIT * relaxation_time_s:
        return []
    text = (
        f"RK2 is unstable here: the largest time step {dt:g} s exceeds 2 tau = {2 * relaxation_time_s:g} s "
        f"(dt / tau = {dt / relaxation_time_s:.3g})"
    )
    if not allow_unstable:
        raise InputError(
            text,
            file=file,
            key="viscoelastic.integrator",
            expected='integrator = "exact" (unconditionally stable), time steps <= 2 tau, or allow_unstable = true',
        )
    return [text + "; run anyway because viscoelastic.allow_unstable = true"]
