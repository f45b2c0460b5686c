"""A scene (`Scene`): the blocks and fixed boxes of one state of a trial (A or B),
validated by lgp.scene.validation."""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Iterable

import numpy as np

from lgp.scene.solids import Block, FixedBox
from lgp.scene.validation import validate_scene


@dataclass(frozen=True)
class Scene:
    """Blocks plus fixed obstacles; `label` says where it came from (``7H-B``)."""

    blocks: tuple[Block, ...]
    fixed: tuple[FixedBox, ...] = ()
    label: str = "scene"

    def __post_init__(self):
        object.__setattr__(self, "blocks", tuple(self.blocks))
        object.__setattr__(self, "fixed", tuple(self.fixed))

    def __len__(self) -> int:
        return len(self.blocks)

    def __iter__(self):
        return iter(self.blocks)

    @property
    def names(self) -> list[str]:
        return [b.name for b in self.blocks]

    def block(self, name: str) -> Block:
        for b in self.blocks:
            if b.name == name:
                return b
        raise KeyError(f"{self.label}: no block named {name!r}")

    def with_blocks(self, blocks: Iterable[Block]) -> "Scene":
        return replace(self, blocks=tuple(blocks))

    @property
    def positions(self) -> np.ndarray:
        """Block centres p_WB, shape (n, 3), in block order."""
        return np.array([b.p_WB for b in self.blocks]).reshape(-1, 3)

    def validate(self) -> "Scene":
        """Raise StimulusError on the first broken rule; return self when valid."""
        validate_scene(self)
        return self
