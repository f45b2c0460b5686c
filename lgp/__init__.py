"""Logic-geometric planning of block-building tasks: scene, support graph,
assignment, symbolic plan (logic layer) and KOMO motion optimisation (geometry).

``lgp.plan`` (lgp/search/: planner="paper", the paper's pipeline of lgp/planner/,
or planner="search") and ``lgp.Plan`` (lgp/planner/) are imported on first use,
and the planner loads Drake only when it plans, so that ``import stimuli`` and the
logic layer stay light.
"""
from lgp.scene import Block, FixedBox, Scene, StimulusError, support_graph  # noqa: F401


def __getattr__(name):
    if name == "plan":
        from lgp import search

        return search.plan
    if name == "Plan":
        from lgp import planner

        return planner.Plan
    raise AttributeError(f"module 'lgp' has no attribute {name!r}")
