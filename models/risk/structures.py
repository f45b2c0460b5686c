"""Reference block structures for the risk model's faithfulness checks and benchmarks.

Each builder returns a validated `lgp.scene.Scene` of 1-inch cubes on the table
(z = 0), built exactly (no rounding), so its stability has a textbook answer.
"""
from __future__ import annotations

import numpy as np

from lgp.paper import BLOCK_SIZE, BUILD_SITE
from lgp.scene import Block, Scene

D = BLOCK_SIZE


def _block(i: int, x: float, y: float, z_bottom: float, yaw: float = 0.0) -> Block:
    return Block(f"b{i}", np.array([x, y, z_bottom + D / 2]), yaw=yaw)


def tower(n: int, p_WS=BUILD_SITE, offsets=None, label: str | None = None) -> Scene:
    """n blocks stacked at the site S; `offsets` (n-1, 2) shifts each block (m)
    relative to the one below it (default: perfectly aligned)."""
    offsets = np.zeros((max(n - 1, 0), 2)) if offsets is None else np.asarray(offsets, float).reshape(-1, 2)
    xy = np.asarray(p_WS, float)
    blocks = [_block(0, xy[0], xy[1], 0.0)]
    for i in range(1, n):
        xy = xy + offsets[i - 1]
        blocks.append(_block(i, xy[0], xy[1], i * D))
    return Scene(blocks, label=label or f"tower{n}").validate()


def line(n: int, p_WS=BUILD_SITE, gap: float = 0.0, label: str | None = None) -> Scene:
    """n blocks side by side along y on the table, `gap` (m) apart (0 = touching)."""
    ys = p_WS[1] + (np.arange(n) - (n - 1) / 2) * (D + gap)
    return Scene([_block(i, p_WS[0], y, 0.0) for i, y in enumerate(ys)], label=label or f"line{n}").validate()


def two_block(offset: float, axis: int = 0, label: str | None = None) -> Scene:
    """A block resting on another, shifted by `offset` (fraction of d) along x or y."""
    shift = np.zeros(2)
    shift[axis] = offset * D
    return tower(2, offsets=[shift], label=label or f"two-block offset {offset:g}d")


def harmonic(n: int, scale: float = 1.0, label: str | None = None) -> Scene:
    """Harmonic overhang stack of n blocks: the k-th block from the top overhangs the
    one below it by scale * d / (2k), all shifts in +x. scale = 1 is the critical
    stack (every partial centre of mass exactly above a supporting edge)."""
    # offsets listed bottom-up: the block at height i (1..n-1) is k = n - i from the top
    offsets = [(scale * D / (2 * (n - i)), 0.0) for i in range(1, n)]
    return tower(n, offsets=offsets, label=label or f"harmonic{n} x{scale:g}")


def staircase(n: int, step: float = 0.2, label: str | None = None) -> Scene:
    """n-block tower with every block shifted `step` * d in +x from the one below."""
    return tower(n, offsets=[(step * D, 0.0)] * (n - 1), label=label or f"staircase{n} {step:g}d")


def bridge(gap: float = 0.5, height: int = 2, top: bool = True, label: str | None = None) -> Scene:
    """Two pillars of `height` blocks `gap` * d apart along x, a lintel spanning them
    and (optionally) a block on the lintel."""
    x0 = BUILD_SITE[0]
    xl, xr = x0 - (D + gap * D) / 2, x0 + (D + gap * D) / 2
    blocks, i = [], 0
    for level in range(height):
        for x in (xl, xr):
            blocks.append(_block(i, x, 0.0, level * D))
            i += 1
    blocks.append(_block(i, x0, 0.0, height * D))
    if top:
        blocks.append(_block(i + 1, x0, 0.0, (height + 1) * D))
    return Scene(blocks, label=label or f"bridge gap {gap:g}d").validate()


def pyramid(label: str = "pyramid 3-2-1") -> Scene:
    """A row of 3 blocks, 2 on the seams, 1 on top."""
    x0 = BUILD_SITE[0]
    blocks = [_block(i, x0 + (i - 1) * D, 0.0, 0.0) for i in range(3)]
    blocks += [_block(3 + i, x0 + (i - 0.5) * D, 0.0, D) for i in range(2)]
    blocks.append(_block(5, x0, 0.0, 2 * D))
    return Scene(blocks, label=label).validate()


def grid(nx: int, ny: int, layers: int = 1, label: str | None = None) -> Scene:
    """A wall/floor of touching blocks: nx along x, ny along y, `layers` high."""
    x0, y0 = BUILD_SITE[0] - (nx - 1) * D / 2, BUILD_SITE[1] - (ny - 1) * D / 2
    blocks = []
    for k in range(layers):
        for i in range(nx):
            for j in range(ny):
                blocks.append(_block(len(blocks), x0 + i * D, y0 + j * D, k * D))
    return Scene(blocks, label=label or f"grid {nx}x{ny}x{layers}").validate()
