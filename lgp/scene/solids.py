"""The solids of a scene: a block (`Block`), a fixed box (`FixedBox`), the
tolerances and workspace bounds every check of lgp.scene uses, and the error of
a broken stimulus rule (`StimulusError`).

Frames follow Drake's monogram notation: W is the world frame on the table top
(z = 0 is the table surface, x away from the agent, y to its left); B is a block's
body frame at its centre; `p_WB` is the block centre in W and `yaw` its rotation
about z, so X_WB = RigidTransform(RotationMatrix.MakeZRotation(yaw), p_WB).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from lgp.geometry import rectangle, yaw_direction
from lgp.paper import BLOCK_SIZE

#: Two solids may interpenetrate by at most this much (m) and still count as
#: touching: trial files are written to 0.1 mm, and a touching pair computed in
#: floating point overlaps by ~1e-17 m.
OVERLAP_TOLERANCE = 1e-4
#: A block rests on a surface when its bottom face is within this distance (m) of
#: that surface's top face (and their footprints overlap by more than
#: MIN_SUPPORT_AREA).
CONTACT_TOLERANCE = 1e-4
#: Smallest footprint overlap (m^2) that counts as support: 1 mm x 1 mm.
MIN_SUPPORT_AREA = 1e-6
#: Name of the table in support graphs.
TABLE = "table"

#: The workspace of a table-top task, which every solid (block or fixed box) of a
#: scene must lie in: centre within |x|, |y| <= WORKSPACE_XY and WORKSPACE_Z[0] <=
#: z <= WORKSPACE_Z[1] (m), every edge longer than SOLID_SIZE[0] and at most
#: SOLID_SIZE[1] (m), yaw within one turn (|yaw| <= 2 pi). Not the paper's numbers:
#: bounds well beyond the arm's reach and the 1-inch blocks, there to refuse absurd
#: input (a size of 1e300 hangs a physics engine) before anything plans or simulates.
WORKSPACE_XY = 2.0
WORKSPACE_Z: tuple[float, float] = (0.0, 2.0)
SOLID_SIZE: tuple[float, float] = (1e-3, 0.5)


class StimulusError(ValueError):
    """A trial, state or block breaks a rule of the stimulus format.

    The message names the trial and state (e.g. ``7H-B``), the block and the rule.
    """


@dataclass(frozen=True)
class Block:
    """A cuboid block: name, centre `p_WB`, yaw about world z, colour, size (m)."""

    name: str
    p_WB: np.ndarray
    yaw: float = 0.0
    colour: str = "natural"
    size: np.ndarray = field(default_factory=lambda: np.full(3, BLOCK_SIZE))

    def __post_init__(self):
        object.__setattr__(self, "p_WB", np.asarray(self.p_WB, dtype=float).reshape(3))
        object.__setattr__(self, "size", np.asarray(self.size, dtype=float).reshape(3))
        object.__setattr__(self, "yaw", float(self.yaw))

    @property
    def X_WB(self):
        """Pose of the block frame in the world, as a Drake RigidTransform."""
        from pydrake.math import RigidTransform, RotationMatrix

        return RigidTransform(RotationMatrix.MakeZRotation(self.yaw), self.p_WB)

    @property
    def bottom(self) -> float:
        return float(self.p_WB[2] - self.size[2] / 2)

    @property
    def top(self) -> float:
        return float(self.p_WB[2] + self.size[2] / 2)

    def footprint(self) -> np.ndarray:
        """Corners (4, 2) of the block's outline seen from above, counter-clockwise."""
        return rectangle(self.p_WB[:2], self.size[:2], self.yaw)

    def outline(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(centre, half extents, unit edge direction), each (2,), of the outline seen from above."""
        return self.p_WB[:2], self.size[:2] / 2, yaw_direction(self.yaw)

    def moved_to(self, p_WB, yaw: float | None = None) -> "Block":
        return replace(self, p_WB=np.asarray(p_WB, float), yaw=self.yaw if yaw is None else yaw)


@dataclass(frozen=True)
class FixedBox:
    """An axis-aligned box that never moves (a wall or the floor of the bucket).

    `name` is the obstacle it belongs to (several boxes may share it, e.g. the five
    boxes of the bucket); `p_WO` is the box centre and `size` its full extents.
    """

    name: str
    p_WO: np.ndarray
    size: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "p_WO", np.asarray(self.p_WO, dtype=float).reshape(3))
        object.__setattr__(self, "size", np.asarray(self.size, dtype=float).reshape(3))

    @property
    def bottom(self) -> float:
        return float(self.p_WO[2] - self.size[2] / 2)

    @property
    def top(self) -> float:
        return float(self.p_WO[2] + self.size[2] / 2)

    def footprint(self) -> np.ndarray:
        return rectangle(self.p_WO[:2], self.size[:2], 0.0)

    def outline(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(centre, half extents, unit edge direction), each (2,), of the outline seen from above."""
        return self.p_WO[:2], self.size[:2] / 2, yaw_direction(0.0)
