"""Closed forms, obstacle geometry and problem validation (numpy only, no dolfinx)."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fem_reference import FEContactProblem, RigidCylinder, RigidPlane, RigidSurface, Roller
from fem_reference import closed_forms as cf
from fem_reference.problem import resolve_free_directions

pytestmark = pytest.mark.fe

ROOT = Path(__file__).resolve().parents[2]


def test_import_does_not_load_dolfinx():
    """Invariant: importing fem_reference (and its numpy modules) must not import dolfinx."""
    code = ("import sys; import fem_reference, fem_reference.closed_forms, fem_reference.meshes; "
            "import fem_reference.contact, fem_reference.contact_vi, fem_reference.krylov, fem_reference.scene_run; "
            "bad = [m for m in ('dolfinx', 'petsc4py', 'ufl', 'gmsh') if m in sys.modules]; "
            "print(bad); sys.exit(1 if bad else 0)")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr


def test_hertz_line_contact_formulas():
    """Hertz: a = sqrt(4 P' R / (pi E*)), p0 = 2 P' / (pi a), integral of p(x) = P'."""
    h = cf.HertzLine(0.5, 20.0, 10.35, 0.42)
    es = 10.35 / (1 - 0.42**2)
    assert h.contact_modulus_mpa == pytest.approx(es)
    assert h.half_width_mm == pytest.approx(math.sqrt(4 * 0.5 * 20.0 / (math.pi * es)))
    assert h.peak_pressure_mpa == pytest.approx(2 * 0.5 / (math.pi * h.half_width_mm))
    x = np.linspace(-h.half_width_mm, h.half_width_mm, 200001)
    assert np.trapezoid(h.pressure_mpa(x), x) == pytest.approx(0.5, rel=1e-5)
    h2 = cf.HertzLine.for_half_width(1.0, 20.0, 10.35, 0.42)
    assert h2.half_width_mm == pytest.approx(1.0)
    assert cf.hertz_line_contact(h2.load_per_length_n_per_mm, 20.0, 10.35, 0.42)[0] == \
        pytest.approx(1.0)
    # fitted half-width of a sampled Hertz profile
    xs = np.linspace(0, 1.2, 50)
    a, p0 = cf.fit_elliptic_half_width(xs, h2.pressure_mpa(xs))
    assert a == pytest.approx(1.0, rel=1e-9) and p0 == pytest.approx(h2.peak_pressure_mpa)


def test_confined_modulus_is_lambda_plus_two_mu():
    """Confined compression: E' = E(1-nu)/((1+nu)(1-2nu)) = lambda + 2 mu; p = E' d / h."""
    e, nu = 10.35, 0.42
    lam, mu = e * nu / ((1 + nu) * (1 - 2 * nu)), e / (2 * (1 + nu))
    assert cf.confined_modulus(e, nu) == pytest.approx(lam + 2 * mu)
    p = cf.confined_compression_pressure(e, nu, 2.0, 0.1)
    assert p == pytest.approx((lam + 2 * mu) * 0.05)
    assert cf.confined_compression_displacement(e, nu, 2.0, p) == pytest.approx(0.1)


def test_observed_order():
    """Richardson: values f(h) = f* + C h^2 on h, h/2, h/4 give order 2 and the limit f*."""
    vals = np.array([1.0 + 0.3 * h**2 for h in (0.4, 0.2, 0.1)])
    assert cf.observed_order(vals) == pytest.approx(2.0)
    assert cf.richardson_extrapolate(vals) == pytest.approx(1.0)
    assert np.allclose(cf.observed_order_vs_exact(vals - 1.0), 2.0)


def test_obstacle_gaps():
    """Gap along the obstacle normal: plane (exact), cylinder (radial), triangulated surfaces."""
    pts = np.array([[0.3, 0.2, 1.5], [2.0, -1.0, 0.25]])
    plane = RigidPlane((0, 0, 0), (0, 0, 2))
    g, n = plane.gap_and_normal(pts)
    assert np.allclose(g, pts[:, 2]) and np.allclose(n, [0, 0, 1])
    # triangulated version of the same plane
    v = np.array([[-10, -10, 0], [10, -10, 0], [10, 10, 0], [-10, 10, 0]], float)
    surf = RigidSurface(v, np.array([[0, 1, 2], [0, 2, 3]]))
    gs, ns = surf.gap_and_normal(pts)
    assert np.allclose(gs, g) and np.allclose(ns, n)
    flipped = RigidSurface(v, np.array([[0, 1, 2], [0, 2, 3]]), flip_normals=True)
    assert np.allclose(flipped.gap_and_normal(pts)[0], -g)
    cyl = RigidCylinder((0, 0, 5), (0, 1, 0), 4.0)
    gc, nc = cyl.gap_and_normal(np.array([[0.0, 3.0, 0.5], [3.0, 0.0, 5.0]]))
    assert np.allclose(gc, [0.5, -1.0]) and np.allclose(nc, [[0, 0, -1], [1, 0, 0]])
    # finely triangulated cylinder: gap close to the analytic radial gap
    th = np.linspace(-0.5, 0.5, 201)
    verts = np.array([[4 * np.sin(t), y, 5 - 4 * np.cos(t)] for t in th for y in (-1.0, 1.0)])
    tris = []
    for i in range(len(th) - 1):
        a, b, c, d = 2 * i, 2 * (i + 1), 2 * (i + 1) + 1, 2 * i + 1
        tris += [(a, b, c), (a, c, d)]
    tsurf = RigidSurface(verts, np.array(tris))
    q = np.array([[0.37, 0.1, 0.6], [-0.9, -0.2, 0.9]])
    gt, nt = tsurf.gap_and_normal(q)
    if gt[0] < 0:
        gt, nt = -gt, -nt
    ga, na = cyl.gap_and_normal(q)
    assert np.allclose(gt, ga, atol=2e-4)
    assert np.allclose(nt, na, atol=5e-3)


def test_problem_validation():
    """Bad input is refused with a message naming the field."""
    kw = dict(mesh=None, youngs_modulus_mpa=10.0, poissons_ratio=0.3,
              obstacle=RigidPlane((0, 0, 0), (0, 0, 1)), force_n=(0, 0, 1.0))
    with pytest.raises(ValueError, match="poissons_ratio"):
        FEContactProblem(**{**kw, "poissons_ratio": 0.5})
    with pytest.raises(ValueError, match="force_n"):
        FEContactProblem(**{**kw, "force_n": (0, 0, 0)})
    with pytest.raises(ValueError, match="element"):
        FEContactProblem(**{**kw, "element": "P3"})
    assert FEContactProblem(**{**kw, "poissons_ratio": 0.499}).resolved_element() == "TH"
    assert FEContactProblem(**kw).resolved_element() == "P2"
    d = FEContactProblem(**{**kw, "force_n": (1.0, 0, 1.0)}).free_directions()
    assert np.allclose(d, [[2**-0.5, 0, 2**-0.5]])
    with pytest.raises(ValueError, match="roller"):
        resolve_free_directions(("x", "z"), np.array([0, 0, 1.0]), (Roller(4, "x"),))
    with pytest.raises(ValueError, match="no component"):
        resolve_free_directions(("x",), np.array([0, 0, 1.0]))
    with pytest.raises(ValueError, match="degenerate"):
        RigidSurface(np.zeros((3, 3)), np.array([[0, 1, 2]]))
