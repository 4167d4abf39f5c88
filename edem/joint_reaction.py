"""OpenSim load conventions: axes presets and JointReaction columns (which body, which frame, which point).

OpenSim's ground and body frames have x anterior, y superior (up), z to the right. The scene
axes of this project's joints are x lateral (right, for a right ankle), y anterior, z superior,
so the ``"opensim"`` preset maps OpenSim (x, y, z) onto the scene as (z, x, y): a rotation, no
mirror. A load file never has its axes guessed: `[load] axes` says how they map.

A JointReaction ReactionLoads column is named ``<joint>_on_<body>_in_<frame>_<c>``: the force
(``fx, fy, fz`` in N) and moment (``mx, my, mz`` in N m) that the joint applies *on* ``<body>``,
*expressed in* ``<frame>``'s axes, the moment taken *about* the joint centre whose position
(``px, py, pz`` in m) is given in that frame too. The scene's load presses the mobile body into
the fixed one: minus a reaction on the mobile body (its equilibrium), a reaction on the fixed
body as is (action and reaction); edem.loads applies that sign.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

AXIS_NAMES = ("x", "y", "z")
AXES_PRESETS = {
    "same": ("x", "y", "z"),
    # scene x (right) = OpenSim z, scene y (anterior) = OpenSim x, scene z (up) = OpenSim y
    "opensim": ("z", "x", "y"),
}
_JOINT_REACTION = re.compile(r"^(?P<joint>.+?)_on_(?P<body>.+)_in_(?P<frame>.+)$")


def axes_matrix(spec: str | list[str] | tuple[str, ...]) -> np.ndarray:
    """(3, 3) rotation A with scene = A @ file, from a preset name or three signed file axes.

    ``["z", "-x", "y"]`` reads: scene x = file z, scene y = -file x, scene z = file y.
    Raises ValueError (with the reason) unless every file axis is used once and the map is a
    rotation (a mirror would turn moments and positions into their mirror images).
    """
    names = AXES_PRESETS.get(spec) if isinstance(spec, str) else tuple(spec)
    if names is None:
        raise ValueError(f"unknown axes preset {spec!r}")
    if len(names) != 3 or not all(isinstance(n, str) for n in names):
        raise ValueError("three axis names are needed, one per scene axis")
    a = np.zeros((3, 3))
    for row, name in enumerate(names):
        sign = -1.0 if name.startswith("-") else 1.0
        axis = name.lstrip("+-").lower()
        if axis not in AXIS_NAMES:
            raise ValueError(f"{name!r} is not an axis name")
        a[row, AXIS_NAMES.index(axis)] = sign
    if not np.allclose(np.abs(a).sum(axis=0), 1.0):
        raise ValueError("each file axis must appear exactly once")
    if np.linalg.det(a) < 0:
        raise ValueError("the mapping is a mirror image (determinant -1): negate one more axis or swap two")
    return a


@dataclass(frozen=True)
class JointReactionColumns:
    """The conventions encoded in one JointReaction column prefix."""

    prefix: str
    joint: str
    body: str  # the load is the one applied on this body
    frame: str  # the components (and the point) are expressed in this frame

    @staticmethod
    def parse(prefix: str) -> "JointReactionColumns | None":
        match = _JOINT_REACTION.match(prefix)
        if match is None:
            return None
        return JointReactionColumns(prefix, match["joint"], match["body"], match["frame"])

    def names(self, quantity: str) -> list[str]:
        """The three column names of 'f', 'm' or 'p'."""
        return [f"{self.prefix}_{quantity}{c}" for c in AXIS_NAMES]


def transfer_moment(moment_nmm: np.ndarray, force_n: np.ndarray, point_mm: np.ndarray, reference_point_mm: np.ndarray) -> np.ndarray:
    """(n, 3) moment about the reference point G of a load given about ``point_mm``: M_G = M_P + (P - G) x F."""
    return moment_nmm + np.cross(point_mm - reference_point_mm, force_n)
