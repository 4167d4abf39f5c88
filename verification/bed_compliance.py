"""The bed's compliance against a reference's: the bed's deflection under the reference's own contact pressure.

A DEM-FE comparison mixes two errors: the bed's operator (how the layers deflect under a given
pressure) and the contact solve that finds the pressure. This check takes the second out. At the
reference's pose, where the reference is in contact its deformed articular surfaces touch, so the
layers there have deflected by the overlap of the undeformed surfaces along each spring,
d = t - h0 + g u: the overlap at M's reference pose plus the approach of the reference's rigid
motion u along the spring (g = (n, (c - G) x n)), linearised as the DEM's solve and the FE's
small-sliding contact both take it (re-casting the rays at the moved pose instead reads the DEM's
own solution on the subject-like ankle 3 % short). Put the reference's own contact pressure
through the bed's compliance, w = C (p A) (:func:`edem.thin_layer_contact.overlap_and_deflection_mm`),
and a bed exact to the reference gives w = d at every spring in contact. Reported per time point as the ratio of the
integrals over the contact, int w dA / int d dA, and the same over the contact's interior and over
the band within one layer thickness of its edge (the width over which a layer's edge effects
decay: its total thickness T, the median over the contact). The contact is where the reference's
pressure and d are both positive; where the reference presses but d <= 0 its layers' bulge closed
the gap, w and d change sign there and a ratio of integrals would mean nothing, so those springs
are counted (``n_bulge``) but not compared. A ratio below 1 is a bed stiffer than the reference.
The reference's pressure must be resolved: an FE's nodal pressure (a lumped L2 projection onto
P1) spreads the contact's edge over a face element, which reads as a stiff bed
(docs/method.md#7-comparison-metrics).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from edem.mechanics import generalised_directions
from edem.pressure_metrics import pressure_field_on_mobile
from edem.raycast import RayCaster
from edem.resultdir import read_result_dir
from edem.scene import Scene, load_scene
from edem.springs import Placement, spring_geometry
from edem.thin_layer_contact import overlap_and_deflection_mm
from geometries.errors import InputError
from verification.metrics import frame_index, sample_onto

#: the regions of the contact the ratio is given over
REGIONS = ("contact", "interior", "edge")
#: a case's metrics: per region, the ratio minus 1 (signed: negative where the bed is stiffer than
#: the reference), the one farthest from 0 over the loaded time points
BED_COMPLIANCE_DESCRIPTIONS = {
    f"bed_deflection_{region}_rel_error": f"the bed's deflection under the reference's own contact pressure over the deflection at the reference's pose, minus 1, "
                                         f"over the {what} (int w dA / int d dA; negative: the bed stiffer), the largest magnitude over the loaded time points, "
                                         "verification.bed_compliance"
    for region, what in zip(REGIONS, ("contact", "contact farther than one layer thickness from its edge", "contact within one layer thickness of its edge"), strict=True)
}
BED_COMPLIANCE_METRICS = tuple(BED_COMPLIANCE_DESCRIPTIONS)
#: a per-load analysis's reported columns (name, metric) beside a coupled bed's errors: the contact and its edge band
BED_COMPLIANCE_QUANTITIES = (("bed deflection under the FE's pressure, contact", "bed_deflection_contact_rel_error"),
                             ("bed deflection under the FE's pressure, edge band", "bed_deflection_edge_rel_error"))


def add_bed_compliance(comparison: dict[str, Any], rows: list[dict[str, Any]]) -> dict[str, float]:
    """The case metrics :data:`BED_COMPLIANCE_METRICS` from :func:`bed_compliance`'s ``rows``,
    each time point's values also put into ``comparison``'s ``per_time`` entries (matched on the
    reference's time ``time_b_s``; :func:`verification.metrics.compare_result_dirs`)."""
    by_time = {row["time_s"]: row for row in rows}
    values: dict[str, list[float]] = {name: [] for name in BED_COMPLIANCE_METRICS}
    for entry in comparison["per_time"]:
        row = by_time.get(entry["time_b_s"])
        if row is None:
            continue  # an unloaded time point: no contact to deflect
        for region, name in zip(REGIONS, BED_COMPLIANCE_METRICS, strict=True):
            ratio = row[f"ratio_{region}"]
            entry[name] = ratio - 1.0 if np.isfinite(ratio) else None  # None: no spring in that region
            if entry[name] is not None:
                values[name].append(entry[name])
    return {name: max(v, key=abs) for name, v in values.items() if v}


def bed_compliance_of_run(dem_dir: str | Path, reference_dir: str | Path) -> list[dict[str, Any]]:
    """:func:`bed_compliance` of the scene a DEM run wrote (``dem_dir``/scene.toml)."""
    scene_file = Path(dem_dir) / "scene.toml"
    return bed_compliance(load_scene(scene_file), reference_dir, scene_file)


def bed_compliance(scene: Scene, reference_dir: str | Path, scene_file: str | Path | None = None) -> list[dict[str, Any]]:
    """The bed of ``scene`` under the contact pressure of the run in ``reference_dir``, per loaded
    time point of the reference (module docstring).

    Each entry: ``time_s``, ``load_n``, ``ratio_<region>`` (int w dA / int d dA over each region
    of :data:`REGIONS`), ``n_<region>`` (springs), ``n_bulge`` (springs the reference presses
    where d <= 0), ``edge_band_mm`` (the band's width, mm).
    InputError (naming ``scene_file``, the scene's file) when the scene has no overlap to deflect (a
    law other than the gap laws, or a bed other than the coupled layer), and naming the
    reference's file when it has no pressure map at a time point.
    """
    reference = read_result_dir(reference_dir)
    series = reference.timeseries
    caster = RayCaster(scene.fixed.vertices_mm, scene.fixed.triangles)
    centroid, normal, area = scene.spring_centroid_mm, scene.spring_normal, scene.spring_area_mm2
    rows = []
    directions = generalised_directions(centroid, normal, scene.reference_point_mm)
    for k, t in enumerate(reference.time_s):
        load_n = float(np.linalg.norm([series[f"force_{x}_n"][k] for x in "xyz"]))
        if load_n == 0.0:
            continue
        motion = np.array([series[f"{q}_{x}_{unit}"][k] for q, unit in (("disp", "mm"), ("rot", "rad")) for x in "xyz"])
        geometry = spring_geometry(centroid, normal, area, Placement.identity(scene.reference_point_mm), caster, scene.fixed_placement(k), scene.cartilage)
        try:
            points, triangles, pressure, at_points = pressure_field_on_mobile(reference.frame(frame_index(reference, k)))
        except ValueError:
            raise InputError(f"time point {k} has no pressure map", file=Path(reference_dir) / "pressure.pvd",
                             expected="pressure_on_mobile_mpa or pressure_mpa on the contact surface") from None
        if at_points:  # an FE contact face's pressure on the points of M under it (M's reference frame)
            pressure_mpa = np.maximum(sample_onto(points, triangles, pressure, centroid), 0.0)
        elif np.array_equal(triangles, scene.mobile.triangles):  # a discrete run of this scene: its springs
            pressure_mpa = np.maximum(pressure[scene.spring_triangle], 0.0)
        else:
            raise InputError(f"time point {k}'s pressure map is neither nodal nor on the DEM's springs", file=Path(reference_dir) / "pressure.pvd",
                             expected="pressure_on_mobile_mpa point data (an FE run) or the DEM scene's own triangulation")
        try:
            overlap, deflection = overlap_and_deflection_mm(scene, geometry, pressure_mpa * area)
        except InputError as exc:
            raise InputError(exc.problem, file=scene_file, key=exc.key, expected=exc.expected) from None
        with np.errstate(invalid="ignore"):  # -inf + inf where a ray meets no F: no thickness there (NaN)
            thickness = overlap + geometry.spring_length_mm  # t, the springs' total T with both layers
        overlap = overlap + directions @ motion  # the approach of the reference's rigid motion along each spring
        rows.append({"time_s": float(t), "load_n": load_n, **_ratios(centroid, area, overlap, deflection, pressure_mpa > 0.0, thickness)})
    return rows


def _ratios(centroid_mm: np.ndarray, area_mm2: np.ndarray, overlap_mm: np.ndarray, deflection_mm: np.ndarray,
            pressed: np.ndarray, thickness_mm: np.ndarray) -> dict[str, Any]:
    """The ratios over the contact (pressed and overlapping springs), its interior and its edge band."""
    contact = pressed & (overlap_mm > 0.0)
    band_mm = float(np.median(thickness_mm[contact])) if contact.any() else 0.0
    outside = ~contact
    distance = cKDTree(centroid_mm[outside]).query(centroid_mm)[0] if outside.any() else np.full(contact.shape, np.inf)
    regions = {"contact": contact, "interior": contact & (distance > band_mm), "edge": contact & (distance <= band_mm)}
    # where the reference presses but the undeformed surfaces do not overlap, its layers' bulge
    # closed the gap (d <= 0): there w and d change sign, so those springs are counted, not compared
    out: dict[str, Any] = {"edge_band_mm": band_mm, "n_bulge": int(np.count_nonzero(pressed & ~contact))}
    for name, where in regions.items():
        needed = float(np.sum(overlap_mm[where] * area_mm2[where]))
        out[f"ratio_{name}"] = float(np.sum(deflection_mm[where] * area_mm2[where])) / needed if needed > 0.0 else float("nan")
        out[f"n_{name}"] = int(where.sum())
    return out
