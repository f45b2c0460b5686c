"""Looking at a solved plan (lgp.planner.Plan): a self-contained 3-D replay and a figure.

    from lgp.app.view import write_html, write_png
    write_html(plan, "7H.html"); write_png(plan, "7H.png")

`write_html` records the arm and blocks into a Drake Meshcat animation
(StartRecording / PublishRecording) and saves `Meshcat.StaticHtml()`: one HTML file
with the three.js viewer inlined, so it opens offline. Meshcat serves on localhost
only while the file is written. The camera opens framed on the table, the arm and
the build site (`Meshcat.SetCameraPose`); each moved block has its own colour by
placement order (`order_colours`, a sequential colormap, legend in the page), and a
caption follows the animation: the trial, the action being played and the effort
so far. `write_png` draws block paths (top and side views) and the speed of every
moved block over time with matplotlib, in the same colours, each action's span
shaded and its effort written above it.
"""
from __future__ import annotations

import html
import json

import numpy as np

from lgp.app.files import atomic_path, write_text_atomic
from lgp.paper import BUILD_SITE, DISPLAY_RGB as COLOURS

#: Sequential colormap of placement order (first placed: dark, last: bright).
ORDER_CMAP = "viridis"
#: Blocks the plan does not move.
UNMOVED_RGB = (0.72, 0.72, 0.70)
#: Vertical field of view of the replay's camera, degrees (Meshcat's default is 75).
CAMERA_FOV = 50.0


def placement_order(plan) -> list[str]:
    """Names (in A) of the moved blocks, ordered by their final placement (the build order)."""
    last = {}
    for k, a in enumerate(plan.actions):
        if type(a).__name__ == "Place":
            last[a.block] = k
    return sorted(last, key=last.get)


def order_colours(plan) -> dict[str, tuple[float, float, float]]:
    """RGB of every block of A: moved blocks by placement order on ORDER_CMAP, others grey."""
    from matplotlib import colormaps

    cmap = colormaps[ORDER_CMAP]
    order = placement_order(plan)
    n = len(order)
    colours = {b.name: UNMOVED_RGB for b in plan.initial.blocks}
    for k, name in enumerate(order):
        colours[name] = tuple(float(c) for c in cmap(0.05 + 0.9 * (k / (n - 1) if n > 1 else 0.5))[:3])
    return colours


def camera_frame(plan) -> tuple[np.ndarray, np.ndarray]:
    """(p_WC, p_WT): a camera on the agent's side, above the table, looking at the work.

    The target is the centre of every block position of A and B and the build site,
    raised so the arm hanging from its overhead mount stays in view.
    """
    P = np.vstack([plan.p_WB[n][[0, -1]] for n in plan.p_WB] + [np.array([[*BUILD_SITE, 0.0]])])
    lo, hi = P.min(axis=0), P.max(axis=0)
    centre = (lo + hi) / 2
    reach = max(float(np.max(hi[:2] - lo[:2])), 0.3)
    p_WT = np.array([centre[0] + 0.08, centre[1], 0.30])
    p_WC = p_WT + np.array([-0.95, -0.55, 0.45]) * (0.95 + 0.7 * reach)
    return p_WC, p_WT


def script_json(data) -> str:
    """JSON safe to put inside a <script> element of an HTML page: ``<``, ``>`` and
    ``&`` as \\u escapes (so text such as ``</script><script>...`` from a trial
    file cannot close the element and run), and U+2028/U+2029 too (line
    terminators in older JavaScript). The value a script reads is unchanged."""
    text = json.dumps(data)
    for char, escape in (("<", "\\u003c"), (">", "\\u003e"), ("&", "\\u0026"),
                         ("\u2028", "\\u2028"), ("\u2029", "\\u2029")):
        text = text.replace(char, escape)
    return text


def _caption_data(plan, title: str) -> dict:
    from lgp.planner import PHASE_DURATION
    from models.effort import cumulative_effort, kinetic_energy_by_action

    cum = cumulative_effort(plan)
    energies = kinetic_energy_by_action(plan) if plan.actions else []
    return {
        "title": title,
        "phase": PHASE_DURATION,
        "t0": float(plan.t[0]),
        "tau": plan.tau,
        "actions": [str(a) for a in plan.actions],
        "action_effort": [round(float(e), 5) for e in energies],
        "cumulative": [round(float(c), 5) for c in cum],
        "total": float(cum[-1]),
    }


def _gradient_css(n: int) -> str:
    from matplotlib import colormaps

    cmap = colormaps[ORDER_CMAP]
    stops = ", ".join(f"rgb({', '.join(str(round(255 * c)) for c in cmap(0.05 + 0.9 * k / 8)[:3])})" for k in range(9))
    return f"linear-gradient(to right, {stops})"


def caption_html(plan, title: str, back: str | None = None) -> str:
    """The overlay of a replay: title, action being played, effort so far, colour
    legend, a play/pause button and (`back`, a relative URL) a link back to the page."""
    data = _caption_data(plan, title)
    n = len(placement_order(plan))
    back_link = (f'<a id="lgp-back" href="{html.escape(back)}" style="margin-right:10px">&larr; results page</a>'
                 if back else "")
    return f"""
<div id="lgp-caption" style="position:fixed;left:12px;top:12px;z-index:10;background:rgba(255,255,255,0.92);
 font:14px/1.4 system-ui,sans-serif;color:#111;padding:8px 12px;border-radius:6px;box-shadow:0 1px 4px rgba(0,0,0,.25);max-width:560px">
 <div style="margin-bottom:4px">{back_link}<button id="lgp-play" type="button"
  style="font:inherit;padding:2px 10px;cursor:pointer">&#10074;&#10074; pause</button></div>
 <div id="lgp-title" style="font-weight:700">{html.escape(title)}</div>
 <div id="lgp-action">&nbsp;</div><div id="lgp-effort">&nbsp;</div>
 <div style="display:flex;align-items:center;gap:6px;font-size:12px;margin-top:4px">placed first
  <span style="display:inline-block;width:140px;height:10px;background:{_gradient_css(n)}"></span> last
  ({n} moved blocks; grey: not moved; faint: B)</div>
</div>
<script>
(function () {{
  var D = {script_json(data)};
  var action = document.getElementById('lgp-action'), effort = document.getElementById('lgp-effort');
  var button = document.getElementById('lgp-play');
  function animator() {{ return (typeof viewer !== 'undefined' && viewer.animator) ? viewer.animator : null; }}
  function label() {{ var a = animator(); button.innerHTML = (a && a.playing) ? '&#10074;&#10074; pause' : '&#9654; play'; }}
  button.addEventListener('click', function () {{
    var a = animator(); if (!a) return;
    if (a.playing) a.pause(); else a.play();
    label();
  }});
  function update() {{
    var t = (typeof viewer !== 'undefined' && viewer.animator) ? viewer.animator.time : 0;
    var k = Math.floor((t - D.t0) / D.phase);
    var n = D.actions.length;
    if (n === 0) action.textContent = 'nothing to move';
    else if (k >= n) action.textContent = 'back to rest after action ' + n + ' of ' + n;
    else {{ k = Math.max(k, 0); action.textContent = 'action ' + (k + 1) + ' of ' + n + ': ' + D.actions[k] + '  (' + D.action_effort[k].toFixed(3) + ' J s)'; }}
    var i = Math.max(0, Math.min(D.cumulative.length - 1, Math.round((t - D.t0) / D.tau)));
    effort.textContent = 't = ' + t.toFixed(1) + ' s, effort so far ' + D.cumulative[i].toFixed(3) + ' of ' + D.total.toFixed(3) + ' J s';
  }}
  update(); label();
  setInterval(function () {{ update(); label(); }}, 100);
}})();
</script>
"""


def _quiet_meshcat(Meshcat):
    """A Meshcat server without its "Meshcat listening for connections at
    http://localhost:7000" log line: the replay is saved as a static HTML file and
    needs no server, so the line would only mislead."""
    import logging

    logger = logging.getLogger("drake")
    level = logger.level
    logger.setLevel(max(level, logging.WARNING))
    try:
        return Meshcat()
    finally:
        logger.setLevel(level)


def replay_html(plan, title: str = "", back: str | None = None) -> str:
    """The replay of `plan` as one HTML string (see the module docstring); `back`: a
    relative URL the overlay links to (the results page), or None."""
    from pydrake.geometry import Box, Meshcat, MeshcatVisualizer, MeshcatVisualizerParams, Rgba, Role
    from pydrake.math import RigidTransform, RotationMatrix
    from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
    from pydrake.systems.framework import DiagramBuilder

    from lgp.arm import add_arm
    from lgp.planner import default_arm

    arm = plan.arm or default_arm()
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    add_arm(plant, arm.config)
    plant.Finalize()
    meshcat = _quiet_meshcat(Meshcat)
    MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat, MeshcatVisualizerParams(role=Role.kIllustration, prefix="arm"))
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyContextFromRoot(context)

    colours = order_colours(plan)
    to_A = {b: a for a, b in plan.symbolic.assignment.items()}
    meshcat.SetProperty("/Grid", "visible", False)
    meshcat.SetProperty("/Axes", "visible", False)
    meshcat.SetObject("/table", Box(1.2, 1.2, 0.02), Rgba(0.86, 0.85, 0.82, 1.0))
    meshcat.SetTransform("/table", RigidTransform([0.42, 0.0, -0.01]))
    for i, box in enumerate(plan.initial.fixed):
        meshcat.SetObject(f"/fixed/{box.name}_{i}", Box(*box.size), Rgba(0.45, 0.45, 0.5, 0.6))
        meshcat.SetTransform(f"/fixed/{box.name}_{i}", RigidTransform(box.p_WO))
    for b in plan.target.blocks:  # ghost of the target, in the colour of the block that goes there
        rgb = colours.get(to_A.get(b.name), COLOURS.get(b.colour, (0.5, 0.5, 0.5)))
        meshcat.SetObject(f"/target/{b.name}", Box(*b.size), Rgba(*rgb, 0.22))
        meshcat.SetTransform(f"/target/{b.name}", b.X_WB)
    for b in plan.initial.blocks:
        meshcat.SetObject(f"/blocks/{b.name}", Box(*b.size), Rgba(*colours[b.name], 1.0))

    meshcat.SetCamera(Meshcat.PerspectiveCamera(fov=CAMERA_FOV))
    meshcat.SetCameraPose(*camera_frame(plan))
    meshcat.StartRecording(frames_per_second=1.0 / plan.tau, set_visualizations_while_recording=False)
    for i, t in enumerate(plan.t):
        context.SetTime(float(t))
        plant.SetPositions(plant_context, plan.q[i])
        diagram.ForcedPublish(context)
        for name in plan.p_WB:
            X = RigidTransform(RotationMatrix(plan.R_WB[name][i]), plan.p_WB[name][i])
            meshcat.SetTransform(f"/blocks/{name}", X, time_in_recording=float(t))
    meshcat.StopRecording()
    meshcat.PublishRecording()
    page = meshcat.StaticHtml()
    title = title or f"{plan.initial.label} -> {plan.target.label}"
    page = page.replace("<title>Drake MeshCat</title>", f"<title>{html.escape(title)}</title>", 1)
    if 'name="viewport"' not in page:  # readable on a phone: the page's width is the screen's
        head = page.lower().find("<head>")
        meta = '\n<meta name="viewport" content="width=device-width, initial-scale=1">'
        page = page[:head + 6] + meta + page[head + 6:] if head >= 0 else meta.strip() + "\n" + page
    cut = page.rfind("</body>")
    return page[:cut] + caption_html(plan, title, back) + page[cut:]


def write_html(plan, path, title: str = "") -> str:
    """Write a self-contained replay of `plan` (an lgp.planner.Plan) to `path`."""
    return str(write_text_atomic(replay_html(plan, title), path))


def write_png(plan, path, title: str = "") -> str:
    """Write a figure of block paths (top view x-y, side view x-z) and speeds to `path`."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    from lgp.planner import PHASE_DURATION
    from models.effort import kinetic_energy, kinetic_energy_by_action

    order = placement_order(plan)
    colours = order_colours(plan)
    fig = Figure(figsize=(16, 4.8))
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, 3, gridspec_kw={"width_ratios": [1, 1, 1.5]})
    top, side, speed = axes
    for b in plan.initial.blocks:
        c = colours[b.name]
        p = plan.p_WB[b.name]
        moved = b.name in order
        top.plot(p[:, 1], p[:, 0], color=c, lw=1.6 if moved else 0.8)
        side.plot(p[:, 0], p[:, 2], color=c, lw=1.6 if moved else 0.8)
        top.scatter(p[0, 1], p[0, 0], color=c, edgecolor="k", marker="s", s=30, zorder=3)
        top.scatter(p[-1, 1], p[-1, 0], color=c, edgecolor="k", marker="o", s=30, zorder=3)
    for box in plan.initial.fixed:
        x0, y0 = box.p_WO[0] - box.size[0] / 2, box.p_WO[1] - box.size[1] / 2
        top.add_patch(Rectangle((y0, x0), box.size[1], box.size[0], color="0.6", alpha=0.5))
    top.set(xlabel="y (m, left +)", ylabel="x (m, away from the agent)", title="block paths, top view (square: start, dot: end)")
    top.invert_xaxis()
    top.set_aspect("equal", adjustable="datalim")
    side.set(xlabel="x (m)", ylabel="z (m)", title="side view")
    side.set_aspect("equal", adjustable="datalim")

    # Speed of each block over time; each action's span shaded (alternately), the
    # carrying actions in the carried block's colour, the action's effort above it.
    energies = kinetic_energy_by_action(plan) if plan.actions else []
    top_speed = max((plan.speed(n).max() for n in order), default=0.0) or 1.0
    for k, (a, e) in enumerate(zip(plan.actions, energies)):
        lo, hi = plan.t[0] + k * PHASE_DURATION, plan.t[0] + (k + 1) * PHASE_DURATION
        carried = type(a).__name__ == "Place"
        speed.axvspan(lo, hi, color=colours[a.block] if carried else "0.5", alpha=0.16 if carried else (0.06 if k % 2 else 0.0), lw=0)
        if carried or e > 5e-4:  # a grasp moves no block: 0 J s, left unlabelled
            speed.text((lo + hi) / 2, top_speed * 1.04, f"{e:.3f}", ha="center", va="bottom", fontsize=7, rotation=90)
    for name in order:
        speed.plot(plan.t, plan.speed(name), color=colours[name], lw=1.3)
    speed.set_ylim(0, top_speed * 1.28)
    speed.set(xlabel="time (s)", ylabel="block speed (m/s)",
              title=f"speed per block; shaded: the action carrying it, number: its effort (J s; grasps 0)\n"
                    f"effort {kinetic_energy(plan):.3f} J s over {len(plan.actions)} actions")
    if order:
        n = len(order)
        listed = ListedColormap([colours[name] for name in order])
        sm = ScalarMappable(cmap=listed, norm=BoundaryNorm(np.arange(n + 1) + 0.5, n))
        bar = fig.colorbar(sm, ax=axes, fraction=0.02, pad=0.01, ticks=np.arange(1, n + 1))
        bar.ax.set_yticklabels([f"{k + 1}: {name}" for k, name in enumerate(order)], fontsize=7)
        bar.set_label(f"placement order ({ORDER_CMAP}; grey: not moved)")
    fig.suptitle(title or f"{plan.initial.label} -> {plan.target.label}", y=1.06, fontweight="bold")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight")
    return str(path)
