"""Logic-geometric planning of block-building tasks: scene, support graph,
assignment, symbolic plan (logic layer) and KOMO motion optimisation (geometry).

``lgp.plan`` and ``lgp.Plan`` (lgp/planner/) are imported on first use, and the
planner loads Drake only when it plans, so that ``import stimuli`` and the logic
layer stay light.
"""
from lgp.scene import Block, FixedBox, Scene, StimulusError, support_graph  # noqa: F401


def __getattr__(name):
    if name in ("plan", "Plan"):
        from lgp import planner

        return getattr(planner, name)
    raise AttributeError(f"module 'lgp' has no attribute {name!r}")
