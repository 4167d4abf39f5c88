"""``population``: 1000 seeded subject-like ankles over the stance (EDEM), the research use of the speed.

Each case is the built-in ``subject-stance`` scene (65 time points: the gap law on the subject's
talar and tibial cartilage, thickness measured to the builder's bones) on a subject-like ankle
whose thirteen parameters (eleven of shape, two cartilage thicknesses) are drawn uniformly within
their documented anatomical ranges (:data:`geometries.builders.SUBJECT_RANGES`, without the
thesis geometry's ``plafond_gap_mm``: the tibia is placed with the articular surfaces touching) by
one seeded generator, so the population is the same on every machine. The ankle axis follows each
subject's talar radius. The bed is named in the overrides: the independent springs here (the
speed), the coupled thin layer (the scenes' default) in ``population-coupled``. The report plots
the peak pressure, the mean contact area and the stance-mean centre of pressure against the main
geometry parameters (one point per subject).

The talus is meshed at 1.5 mm (about 1,000 springs instead of 2,600 at the default 0.93 mm): the
population spread, not the mesh error of one subject, is what this campaign measures.
"""

from __future__ import annotations

import numpy as np

from geometries.builders import SUBJECT_RANGES, SUBJECT_THESIS_ONLY
from verification.campaign_model import Campaign, Case, Figure

#: measured: 284 s for the 1000 subjects with --jobs 2 on the shared 2-core machine (load 3-9), on the
#: threshold law; on the gap law and the subjects' cartilage (2026-11-28) a sample of 40 took a median
#: 0.37 s a subject in one process at load 3-4, 185 s projected for 1000 on 2 cores: the figure stands
EXPECTED_TIME_S = 284.0

POPULATION_SCENE = "subject-stance"
POPULATION_SIZE = 1000
POPULATION_SEED = 2026
POPULATION_MESH_MM = 1.5
POPULATION_METRICS = ("a_peak_pressure_mpa", "a_mean_contact_area_mm2", "a_cop_x_mm", "a_cop_y_mm")
#: the geometry parameters the report plots the metrics against
PLOTTED_PARAMETERS = ("talar_radius_mm", "talar_width_mm", "incongruity", "talar_cartilage_mm", "tibial_cartilage_mm", "tilt_deg", "groove_depth_mm")
#: the parameters drawn: the subject-like ankle's with cartilage (its default)
DRAWN_PARAMETERS = tuple(sorted(k for k in SUBJECT_RANGES if k not in SUBJECT_THESIS_ONLY))


def population_parameters(n: int = POPULATION_SIZE, seed: int = POPULATION_SEED) -> list[dict[str, float]]:
    """n subjects: every parameter of :data:`DRAWN_PARAMETERS` uniform in its range, seeded."""
    rng = np.random.default_rng(seed)
    names = DRAWN_PARAMETERS
    low = np.array([SUBJECT_RANGES[k][0] for k in names])
    high = np.array([SUBJECT_RANGES[k][1] for k in names])
    draws = rng.uniform(low, high, size=(n, len(names)))
    return [{k: round(float(v), 6) for k, v in zip(names, row)} for row in draws]


def _case(index: int, params: dict[str, float], coupling: str = "none") -> Case:
    overrides = {f"geometry.{k}": v for k, v in params.items()}
    overrides["cartilage.coupling"] = coupling  # named: "none" (the speed) is not the scene's default
    overrides.update({
        "geometry.mesh_size_mm": POPULATION_MESH_MM,
        "geometry.fixed_mesh_size_mm": POPULATION_MESH_MM,
        "kinematics.axis_point_mm": [0.0, 0.0, -params["talar_radius_mm"]],  # the talar cylinder's axis
    })
    return Case(
        f"subject{index:04d}",
        f"EDEM stance{' on the coupled thin layer' if coupling != 'none' else ''}, subject-like ankle {index} (R {params['talar_radius_mm']:.1f} mm, width "
        f"{params['talar_width_mm']:.1f} mm, cartilage {params['talar_cartilage_mm']:.2f} + {params['tibial_cartilage_mm']:.2f} mm, "
        f"incongruity {params['incongruity']:.2f})",
        POPULATION_SCENE,
        ("edem",),
        POPULATION_METRICS,
        {},  # a population is described, not judged: every subject's outcome is reported
        overrides=overrides,
        options={"frames": "none"},  # the metrics need the time series only: no pressure map to write
        params=params,
    )


def campaign(n: int = POPULATION_SIZE, coupling: str = "none") -> Campaign:
    """The population; ``coupling = "thin-layer"``: the same subjects on the coupled layer (the
    ``population-coupled`` campaign)."""
    cases = tuple(_case(i, p, coupling) for i, p in enumerate(population_parameters(n)))
    names = tuple(c.name for c in cases)
    metrics = ("a_peak_pressure_mpa", "a_mean_contact_area_mm2", "a_cop_x_mm", "a_cop_y_mm")
    figures = (
        Figure("population-distributions", f"Distributions over {n} subjects: peak pressure (MPa), mean contact area (mm^2), stance-mean centre of pressure x (ML), y (AP) (mm)", "histogram", names, y=metrics),
    ) + tuple(
        Figure(
            f"population-{param.replace('_', '-')}",
            f"Peak pressure (MPa), mean contact area (mm^2) and stance-mean centre of pressure x, y (mm) of {n} subjects against {param}",
            "scatter",
            names,
            x=param,
            y=metrics,
        )
        for param in PLOTTED_PARAMETERS
    )
    coupled = coupling != "none"
    return Campaign(
        "population-coupled" if coupled else "population",
        f"{n} seeded subject-like ankles (13 geometry and cartilage parameters uniform in their anatomical ranges) over the stance, EDEM, gap law on measured cartilage"
        + (" on the coupled thin layer (Pade)" if coupled else "")
        + ": distributions of peak pressure, contact area and centre of pressure against the geometry.",
        cases,
        figures,
        (),
    )
