"""Scenes of 1-inch cubes on a table: blocks, fixed obstacles, and the checks a
stimulus must pass before anything plans or simulates on it.

Frames follow Drake's monogram notation: W is the world frame on the table top
(z = 0 is the table surface, x away from the agent, y to its left); B is a block's
body frame at its centre; `p_WB` is the block centre in W and `yaw` its rotation
about z, so X_WB = RigidTransform(RotationMatrix.MakeZRotation(yaw), p_WB).

One idea a module, each importing only those above it (no cycle):

- `solids`: `Block`, `FixedBox`, the tolerances and workspace bounds, `StimulusError`;
- `overlap`: footprint overlap, penetration depth, resting contact, the broad phase;
- `validation`: the rules of a stimulus state (`validate_scene`, `check_solid`), `colour_shortfall`;
- `state`: `Scene` (its `validate` is `validate_scene`);
- `support`: support graphs (`support_graph`, `support_graph_after_move`, `supported_by`).

Everything is importable from ``lgp.scene`` itself.
"""
from __future__ import annotations

from lgp.paper import BLOCK_SIZE, COLOURS  # noqa: F401  (re-exported: one import for callers)
from lgp.scene.overlap import (box_pairs, solid_outlines, resting_candidates, sat_depths,  # noqa: F401
                               bounding_boxes, footprint_overlap_area, horizontal_penetration, may_penetrate,
                               near_pairs, penetration, rests_on)
from lgp.scene.solids import (CONTACT_TOLERANCE, MIN_SUPPORT_AREA, OVERLAP_TOLERANCE, SOLID_SIZE, TABLE,  # noqa: F401
                              WORKSPACE_XY, WORKSPACE_Z, Block, FixedBox, StimulusError)
from lgp.scene.state import Scene  # noqa: F401
from lgp.scene.support import support_graph, support_graph_after_move, supported_by  # noqa: F401
from lgp.scene.validation import check_solid, colour_shortfall, validate_scene  # noqa: F401
