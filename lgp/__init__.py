"""Logic-geometric planning of block-building tasks: scene, support graph,
assignment, symbolic plan (logic layer) and KOMO motion optimisation (geometry)."""
from lgp.scene import Block, FixedBox, Scene, StimulusError, support_graph  # noqa: F401
from lgp.planner import Plan, plan  # noqa: F401,E402
