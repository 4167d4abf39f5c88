"""The built-in stance: the thesis's 65 time points rebuilt from its 7 published ones (docs/references.md#the-thesiss-figures).

Only table 4.3.4.1 is published (7 instants of ankle angle and joint force). The built-in stance
scenes interpolate it with a shape-preserving PCHIP over 65 points 0.01 s apart (as the thesis
sampled), with end values at 0 % and 100 % of stance that are our assumptions, stated here and in
the scene files:
- heel strike (0 %): ankle angle -3 deg (slight plantarflexion), force 20 N superior (first touch);
- toe off (100 %): ankle angle 10 deg, force 100 N superior (unloading, still in contact).
"""

from __future__ import annotations

import numpy as np

from edem.loads import resample_pchip, thesis_stance_table

N_POINTS = 65
DT_S = 0.01
HEEL_STRIKE = (-3.0, (0.0, 0.0, 20.0))  # angle_deg, (ML, PA, SI) N: assumption
TOE_OFF = (10.0, (0.0, 0.0, 100.0))  # assumption


def stance_series() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(time_s (65,), angle_deg (65,), force_n (65, 3) as ML, PA, SI) through the published table."""
    table = thesis_stance_table()
    percent = np.concatenate([[0.0], table.percent_stance, [100.0]])
    angle = np.concatenate([[HEEL_STRIKE[0]], table.angle_deg, [TOE_OFF[0]]])
    force = np.vstack(
        [HEEL_STRIKE[1], np.column_stack([table.force_ml_n, table.force_pa_n, table.force_si_n]), TOE_OFF[1]]
    )
    time_s = DT_S * np.arange(N_POINTS)
    at = 100.0 * time_s / time_s[-1]
    return time_s, resample_pchip(percent, angle, at), resample_pchip(percent, force, at)


def toml_arrays(decimals: int = 4) -> str:
    """The [load] and angle arrays of a stance scene as TOML text (used to write the scene files)."""
    time_s, angle, force = stance_series()
    fmt = lambda x: repr(round(float(x), decimals))  # noqa: E731
    return (
        "time_s = [" + ", ".join(fmt(t) for t in time_s) + "]\n"
        + "force_n = [\n"
        + "".join(f"  [{fmt(f[0])}, {fmt(f[1])}, {fmt(f[2])}],\n" for f in force)
        + "]\n"
        + "angle_deg = [" + ", ".join(fmt(a) for a in angle) + "]\n"
    )
