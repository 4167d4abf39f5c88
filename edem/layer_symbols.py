"""The layer symbols: rational models of a bonded thin layer's compliance (the coupled bed's physics).

Exact compliance of a bonded layer (plane strain)
--------------------------------------------------
A layer 0 < z < h of an isotropic solid (shear modulus G, Poisson's ratio nu) is bonded to a
rigid base at z = 0 (u_x = u_z = 0) and loaded on its frictionless top z = h by a normal pressure
p cos(kx) (sigma_zz = -p cos kx, sigma_xz = 0). With the Airy function
phi = [(A + B kz) cosh kz + (C + D kz) sinh kz] cos kx (sigma_xx = phi_zz, sigma_zz = phi_xx,
sigma_xz = -phi_xz), plane-strain Hooke's law and the four boundary conditions give A..D, and the
top deflection w = -u_z(h) = C(k) p cos kx with, for q = kh and kappa = 3 - 4 nu,

    C(k) G / h = (1 - nu) (kappa sinh 2q - 2q) / (2q [kappa sinh^2 q + q^2 + 4 (1 - nu)^2]).

Limits: q -> 0 gives h / E' (E' = 2G(1 - nu)/(1 - 2nu), the confined modulus: the independent
spring of the bed); q -> inf gives (1 - nu)/(G k), the half-space. Its Taylor series in x = q^2 is

    C G / h = c0 + c1 x + c2 x^2 + ...,   c0 = (1 - 2nu) / (2(1 - nu)) = G / E',
    c1 = nu (4 nu - 1) / (6 (1 - nu)^2),
    c2 = -(16 nu^3 + 76 nu^2 - 30 nu + 3) / (120 (1 - nu)^3).

c1 = 1/3 at nu = 1/2 is the classical incompressible thin-layer law w = -(h^3 / 3G) lap p;
c2 < 0 for every nu in [0, 1/2].

[1/1] Pade in x
---------------
C G / h ~ (e + a x) / (1 + b x), e = c0, a = c1 + e b. For nu > 1/4 (c1 > 0), b = -c2 / c1 > 0
matches c1 and c2. For nu < 1/4 that b would be negative (a pole at small kh), so there
b = -2 c1 / e >= 0 instead: c0 and c1 are matched and the short-wave limit a / b = e / 2 stays
positive; at nu = 0 and nu = 1/4 (c1 = 0) the model is the independent springs exactly.
Largest relative error against the exact C for kh <= 1 (kh <= 2), see ``LayerSymbol.error_bound``:
nu 0: 3.0 % (22 %, the independent springs' own error); 0.1: 1.4 %; 0.2: 0.7 %; 0.3: 1.0 % (12 %);
0.42: 0.24 % (6.9 %); 0.45: 0.12 %; 0.49: 0.79 % (2.3 %); 0.499: 1.0 % (1.5 %).
The independent springs (C = h/E') are off by 29 % at nu 0.42 and 98 % at nu 0.499 for kh <= 1.
At short waves the Pade levels off at a/b while the layer stiffens as (1 - nu)/kh: 2-5x too
compliant at kh = 12, which widens contacts (docs/method.md, section 3). ``two_pole_symbol`` adds a
second, short-range term fitted over 0 <= kh <= 12; ``LAYER_SYMBOLS`` names both.

Two layers (the sandwich)
-------------------------
Two flat layers h1, h2, each bonded to its rigid base and frictionless against the other, carry
the same pressure p cos(kx) on both faces (action and reaction) and no shear on either, so each
is the problem above and the bones approach by (C(k; h1) + C(k; h2)) p: the sandwich's symbol is
the sum of the layers' (docs/method.md checks it against the two-layer stack solved directly).
Its Taylor series has c1 (h1^3 + h2^3) / G in the k^2 term, a quarter of one layer of thickness
h1 + h2 for equal layers; at short waves it is two half-spaces, 2 (1 - nu) / (G k).

Each symbol is a ``LayerSymbol``: a local part and screened-Poisson terms, which the layer
operator (``edem.thin_layer``) turns into sparse surface operators, one set per layer.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np


def exact_layer_compliance(kh: np.ndarray, poissons_ratio: float) -> np.ndarray:
    """C G / h of the bonded layer under p cos(kx) (module docstring), dimensionless, shape of ``kh``."""
    nu = poissons_ratio
    given = np.asarray(kh, float)
    q = np.minimum(given, 150.0)  # beyond, sinh overflows and C G/h = (1 - nu)/q (the half-space) to e^-300
    kappa = 3.0 - 4.0 * nu
    small = q < 1e-4
    qs = np.where(small, 1.0, q)
    value = (1.0 - nu) * (kappa * np.sinh(2.0 * qs) - 2.0 * qs) / (2.0 * qs * (kappa * np.sinh(qs) ** 2 + qs * qs + 4.0 * (1.0 - nu) ** 2))
    c0, c1, _ = taylor_coefficients(nu)
    return np.where(small, c0 + c1 * q * q, np.where(given > 150.0, (1.0 - nu) / np.maximum(given, 150.0), value))


def taylor_coefficients(poissons_ratio: float) -> tuple[float, float, float]:
    """(c0, c1, c2) of C G / h = c0 + c1 (kh)^2 + c2 (kh)^4 + ... (module docstring)."""
    nu = poissons_ratio
    c0 = (1.0 - 2.0 * nu) / (2.0 * (1.0 - nu))
    c1 = nu * (4.0 * nu - 1.0) / (6.0 * (1.0 - nu) ** 2)
    c2 = -(16.0 * nu**3 + 76.0 * nu**2 - 30.0 * nu + 3.0) / (120.0 * (1.0 - nu) ** 3)
    return c0, c1, c2


def pade_coefficients(poissons_ratio: float) -> tuple[float, float, float]:
    """(e, a, b) of C G / h ~ (e + a (kh)^2) / (1 + b (kh)^2), b >= 0 (module docstring)."""
    c0, c1, c2 = taylor_coefficients(poissons_ratio)
    if c1 > 0.0:
        b = -c2 / c1
    elif c1 < 0.0:
        b = -2.0 * c1 / c0
    else:
        b = 0.0
    return c0, c1 + c0 * b, b


@dataclass(frozen=True)
class LayerSymbol:
    """A rational model of the layer's compliance, C G / h ~ local + sum_i s_i / (1 + b_i (kh)^2).

    Each term s_i / (1 + b_i x) is one screened-Poisson smoothing on the surface (:mod:`edem.thin_layer`:
    w = c_loc p + sum_i s_i (h/G) S_i p). ``dirichlet[i]``: whether term i's smoothed field vanishes
    at a free edge (else the edge is natural for it).
    """

    local: float
    strengths: tuple[float, ...] = ()
    screenings: tuple[float, ...] = ()
    dirichlet: tuple[bool, ...] = ()

    def __call__(self, kh: np.ndarray) -> np.ndarray:
        x = np.asarray(kh, float) ** 2
        return self.local + sum(s / (1.0 + b * x) for s, b in zip(self.strengths, self.screenings))

    def error_bound(self, poissons_ratio: float, max_kh: float = 1.0) -> float:
        """Largest relative error against the exact compliance over 0 < kh <= max_kh."""
        kh = np.linspace(1e-3, max_kh, 4001)
        return float(np.max(np.abs(self(kh) / exact_layer_compliance(kh, poissons_ratio) - 1.0)))


def pade_symbol(poissons_ratio: float) -> LayerSymbol:
    """The [1/1] Pade as a LayerSymbol: local a / b and one term -c1 / b (none where b = 0)."""
    e, a, b = pade_coefficients(poissons_ratio)
    _, c1, _ = taylor_coefficients(poissons_ratio)
    if b == 0.0 or abs(c1) <= 1e-12 * e * b:
        return LayerSymbol(e)
    return LayerSymbol(a / b, (-c1 / b,), (b,), (True,))


#: The two-pole symbol is fitted to the exact compliance over 0 <= kh <= this: the shortest waves
#: a spring mesh resolves on a layer, pi h / spacing (6-12 for a 2 mm layer on 0.5-1 mm springs).
TWO_POLE_MAX_KH = 12.0


def _two_pole_terms(c0: float, c1: float, b: np.ndarray, x: np.ndarray, exact: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For screenings b (k, 2) with b[:, 0] < b[:, 1]: the least-squares relative fit over x of
    local + s1/(1 + b1 x) + s2/(1 + b2 x) with C(0) = c0 and C'(0) = c1 held exactly.

    Returns (local (k,), strengths (k, 2), rms relative error (k,)). The two constraints leave s1
    free: C = c0 + s1 u1 + s2 u2 with u_i = 1/(1 + b_i x) - 1 and s2 = -(c1 + s1 b1) / b2.
    """
    u1 = 1.0 / (1.0 + b[:, :1] * x) - 1.0
    u2 = 1.0 / (1.0 + b[:, 1:] * x) - 1.0
    base = (c0 - c1 / b[:, 1:] * u2) / exact  # (k, n) relative, at s1 = 0
    slope = (u1 - b[:, :1] / b[:, 1:] * u2) / exact
    s1 = ((1.0 - base) * slope).sum(axis=1) / np.maximum((slope * slope).sum(axis=1), 1e-300)
    s2 = -(c1 + s1 * b[:, 0]) / b[:, 1]
    rms = np.sqrt(((base + s1[:, None] * slope - 1.0) ** 2).mean(axis=1))
    return c0 - s1 - s2, np.column_stack([s1, s2]), rms


def _definiteness_margin(local: np.ndarray, s: np.ndarray, b: np.ndarray) -> np.ndarray:
    """local + min(0, min over x >= 0 of g(x)), g(x) = s1/(1 + b1 x) + s2/(1 + b2 x): a lower bound
    (in h/G) of the compliance C on any mesh (``two_pole_symbol``). Rows of s, b: (k, 2).

    With one mass M and stiffness K, both H_i = M + b_i K are diagonal in the basis of K v = lam M v,
    where the two terms weigh each mode by g(lam); bounded below by min(0, min g) times a
    projection, they leave C >= local + min(0, min g). Holding a negative term's field at zero on
    an edge only raises it. g is smallest at x = 0, at infinity (where it is 0) or at its one
    stationary point, which a pair of opposite signs can have.
    """
    lowest = np.minimum(s.sum(axis=1), 0.0)  # g(0); g(inf) = 0
    with np.errstate(invalid="ignore", divide="ignore"):
        # g'(x) = 0: (1 + b2 x) sqrt(-s1 b1) = (1 + b1 x) sqrt(s2 b2) for s1 < 0 < s2 (and the mirror).
        r1, r2 = np.sqrt(np.abs(s[:, 0] * b[:, 0])), np.sqrt(np.abs(s[:, 1] * b[:, 1]))
        x = (r2 - r1) / (r1 * b[:, 1] - r2 * b[:, 0])
        inner = s[:, 0] / (1.0 + b[:, 0] * x) + s[:, 1] / (1.0 + b[:, 1] * x)
    stationary = (s[:, 0] * s[:, 1] < 0.0) & np.isfinite(x) & (x > 0.0)
    return local + np.minimum(lowest, np.where(stationary, inner, 0.0))


@functools.lru_cache(maxsize=64)
def two_pole_symbol(poissons_ratio: float) -> LayerSymbol:
    """Two screened-Poisson terms fitted to the exact compliance for 0 <= kh <= TWO_POLE_MAX_KH.

    The Pade has one term, so it levels off at short waves (C -> a/b) where the layer, like a
    half-space, gets stiffer as (1 - nu)/kh: its contact edges are too soft. Two terms of opposite
    sign follow the exact curve over the whole range (a bulge term, and a short-range term for the
    surface's sag around a load). Fit: C(0) = G/E' and the thin-layer coefficient c1 exactly, the
    rest by least squares in relative error (a 61 x 61 grid of screenings, then Nelder-Mead), among
    the fits whose compliance stays, on any mesh, above half the smaller of its own limits C(0) =
    G/E' and C(inf) = local (``_definiteness_margin``; the Pade's bound is G/E' itself). A term
    with s_i < 0 (the bulge) vanishes on a free edge like the Pade's; a term with s_i > 0 is
    natural there (held at zero it would lower the bound). Largest relative error for
    0 <= kh <= 12: 4.2 % (nu -> 1/2), 2-4 % from nu 0 up, 4.7 % at nu = -0.5.
    """
    from scipy.optimize import minimize

    c0, c1, _ = taylor_coefficients(poissons_ratio)
    q = np.concatenate([np.linspace(0.0, 1.0, 51), np.geomspace(1.0, TWO_POLE_MAX_KH, 200)[1:]])
    x, exact = q * q, exact_layer_compliance(q, poissons_ratio)
    grid = np.linspace(np.log(1e-3), np.log(1e2), 61)
    i, j = np.triu_indices(grid.size, 1)
    b = np.exp(np.column_stack([grid[i], grid[j]]))
    local, s, rms = _two_pole_terms(c0, c1, b, x, exact)
    rms = np.where(_definiteness_margin(local, s, b) >= 0.5 * np.minimum(local, c0), rms, np.inf)

    def objective(log_b: np.ndarray) -> float:
        pair = np.exp(np.sort(log_b))[None]
        if pair[0, 1] <= pair[0, 0] * (1.0 + 1e-9):
            return np.inf
        lo, st, err = _two_pole_terms(c0, c1, pair, x, exact)
        return float(err[0]) if _definiteness_margin(lo, st, pair)[0] >= 0.5 * min(float(lo[0]), c0) else np.inf

    best = int(np.argmin(rms))
    if not np.isfinite(rms[best]):
        raise ValueError(f"no positive definite two-pole fit at Poisson's ratio {poissons_ratio}")
    refined = minimize(objective, np.log(b[best]), method="Nelder-Mead", options={"xatol": 1e-6, "fatol": 1e-9})
    pair = np.exp(np.sort(refined.x))[None] if refined.fun <= rms[best] else b[best][None]
    lo, st, _ = _two_pole_terms(c0, c1, pair, x, exact)
    strengths = tuple(float(v) for v in st[0])
    return LayerSymbol(float(lo[0]), strengths, tuple(float(v) for v in pair[0]), tuple(v < 0.0 for v in strengths))


#: ``[cartilage] thin_layer_symbol``: the rational model of the layer's compliance.
LAYER_SYMBOLS = {"pade": pade_symbol, "two-pole": two_pole_symbol}
