"""Contact sheet of the trials: start state A and target state B side by side.

    python -m stimuli.sheet --out stimuli.png [--seed 0] [--trials 7E 7H]

Scattered blocks are drawn in one random layout (the seed's); a person can check
the structures at a glance against the paper's Figure 1.
"""
from __future__ import annotations

from lgp.atomic import atomic_path

import numpy as np

import stimuli
from lgp import cli
from dataclasses import replace

from lgp.paper import BLOCK_SIZE, COLOURS, display_hex
from lgp.scene import Block, Scene

FACE_COLOURS = {c: display_hex(c) for c in COLOURS}


def _box_faces(p, size, yaw):
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    corners = np.array([[x, y, z] for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)]) * np.asarray(size) / 2
    v = corners @ R.T + p
    idx = [(0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]
    return [v[list(f)] for f in idx]


def _fit_limits(scene: Scene, margin: float = 0.03):
    """A cube of view around everything in the scene, so small structures stay visible."""
    P = np.vstack([scene.positions] + [f.p_WO[None] for f in scene.fixed])
    lo, hi = P.min(axis=0) - margin, P.max(axis=0) + margin
    half = max((hi - lo)[:2].max() / 2, (hi[2] + margin) / 2, 0.06)
    cx, cy = (lo[:2] + hi[:2]) / 2
    return (cx - half, cx + half), (cy - half, cy + half), (0.0, max(hi[2] + margin, 2 * half * 0.5))


def draw_scene(ax, scene: Scene, title: str = "", limits=None) -> None:
    """Draw blocks (coloured) and fixed boxes (translucent grey) on a 3-D axis."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    for b in scene.blocks:
        ax.add_collection3d(Poly3DCollection(_box_faces(b.p_WB, b.size, b.yaw), facecolor=FACE_COLOURS[b.colour], edgecolor="k", linewidths=0.3))
    for f in scene.fixed:
        ax.add_collection3d(Poly3DCollection(_box_faces(f.p_WO, f.size, 0.0), facecolor=(0.5, 0.5, 0.5, 0.08), edgecolor=(0.3, 0.3, 0.3, 0.4), linewidths=0.2))
    (x0, x1), (y0, y1), (z0, z1) = limits or _fit_limits(scene)
    ax.set_xlim(x0, x1), ax.set_ylim(y0, y1), ax.set_zlim(z0, z1)
    ax.set_box_aspect((x1 - x0, y1 - y0, z1 - z0))
    ax.view_init(elev=22, azim=-160)  # looking from the agent's side, slightly above
    ax.set_xticks([]), ax.set_yticks([]), ax.set_zticks([])
    ax.set_title(title, fontsize=8)


def finished_scene(A: Scene, B: Scene) -> Scene:
    """What the table holds when B is built from A: B's blocks, and every block of A
    that B does not need where A left it (pair 12's bucket keeps its 15 other blocks;
    lgp.assignment: unassigned blocks stay where they are). The one finished table:
    the rendered pictures' B (stimuli.render.pictures_of) is this too."""
    from lgp.assignment import assign_blocks

    used = set(assign_blocks(A, B))
    left = [b for b in A.blocks if b.name not in used]
    taken = {b.name for b in B.blocks}
    left = [replace(b, name=b.name if b.name not in taken else f"{b.name} (left)") for b in left]
    return Scene(tuple(B.blocks) + tuple(left), B.fixed, B.label)


def world_limits(*scenes: Scene, build_site=None, margin: float = 0.03):
    """One view cube holding every scene (and the build site): A and B drawn in it share
    their world axes, so a structure that moves (10E, 10H) is seen to move."""
    P = np.vstack([s.positions for s in scenes] + [f.p_WO[None] for s in scenes for f in s.fixed]
                  + ([np.array([[build_site[0], build_site[1], 0.0]])] if build_site is not None else []))
    merged = Scene(tuple(Block(f"p{k}", p) for k, p in enumerate(P)))
    return _fit_limits(merged, margin)


def draw_table(ax, limits, build_site=None) -> None:
    """The table top (z = 0) over the view, and the build site S marked on it."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    (x0, x1), (y0, y1), _ = limits
    top = [np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])]
    ax.add_collection3d(Poly3DCollection(top, facecolor=(0.80, 0.72, 0.60, 0.35), edgecolor=(0.5, 0.45, 0.4, 0.6), linewidths=0.4))
    if build_site is not None:
        r = 0.6 * BLOCK_SIZE
        t = np.linspace(0, 2 * np.pi, 40)
        ax.plot(build_site[0] + r * np.cos(t), build_site[1] + r * np.sin(t), np.zeros_like(t), color="k", lw=0.6, ls="--")
        ax.plot([build_site[0] - r, build_site[0] + r], [build_site[1]] * 2, [0, 0], color="k", lw=0.5)
        ax.plot([build_site[0]] * 2, [build_site[1] - r, build_site[1] + r], [0, 0], color="k", lw=0.5)


def draw_trial(fig, trial, A: Scene, titles=("A: start", "B: finish"), position=(1, 2, 1)) -> list:
    """A and B of `trial` on two 3-D axes of `fig` with the same world axes, the table
    and the build site (dashed ring) drawn in both; B shows the blocks A leaves behind.
    `position` = (rows, columns, index of A); B goes in the next cell. Returns the axes."""
    B = finished_scene(A, trial.target)
    site = trial.initial.build_site
    limits = world_limits(A, B, build_site=site)
    rows, cols, k = position
    axes = []
    for j, (scene, title) in enumerate(((A, titles[0]), (B, titles[1]))):
        ax = fig.add_subplot(rows, cols, k + j, projection="3d")
        draw_table(ax, limits, site)
        draw_scene(ax, scene, title, limits)
        axes.append(ax)
    return axes


def contact_sheet(trials, seed: int = 0, out: str = "stimuli.png") -> str:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    cols = 4  # trials per row, each as A | B
    rows = int(np.ceil(len(trials) / cols))
    fig = Figure(figsize=(cols * 5.0, rows * 2.6))
    FigureCanvasAgg(fig)
    for k, trial in enumerate(trials):
        A = trial.sample_initial(np.random.default_rng(seed))
        r, c = divmod(k, cols)
        for j, (scene, state) in enumerate(((A, "A"), (trial.target, "B"))):
            ax = fig.add_subplot(rows, 2 * cols, r * 2 * cols + 2 * c + j + 1, projection="3d")
            draw_scene(ax, scene, f"{trial.id}-{state}" + (f": {trial.dimension}" if state == "A" else ""))
    fig.suptitle(f"The {len(trials)} trials (A: start, one random layout, seed {seed}; B: finish; each panel zoomed to its content)", fontsize=12)
    fig.subplots_adjust(left=0.01, right=0.99, bottom=0.01, top=0.95, wspace=0.02, hspace=0.12)
    with atomic_path(out) as tmp:
        fig.savefig(tmp, dpi=90)
    return out


PROG = "python -m stimuli.sheet"


def main(argv=None) -> int:
    import argparse

    parser = cli.parser(PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="stimuli.png", type=cli.output_file, help="PNG to write (a missing folder is created)")
    parser.add_argument("--seed", type=cli.seed, default=0)
    parser.add_argument("--trials", nargs="+", type=cli.trial_id, help="trial ids (default: all; case-insensitive)")
    args = parser.parse_args(argv)
    trials = [stimuli.load_trial(t) for t in args.trials] if args.trials else stimuli.load_all()
    print(contact_sheet(trials, args.seed, cli.make_parent(args.out)))
    return 0


if __name__ == "__main__":
    raise SystemExit(cli.run_cli(main, prog=PROG))
