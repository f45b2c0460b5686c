"""Looking at a solved plan (lgp.planner.Plan): a self-contained 3-D replay and a figure.

    from lgp.view import write_html, write_png
    write_html(plan, "7H.html"); write_png(plan, "7H.png")

`write_html` records the arm and blocks into a Drake Meshcat animation
(StartRecording / PublishRecording) and saves `Meshcat.StaticHtml()`: one HTML file
with the three.js viewer inlined, so it opens offline. Meshcat serves on localhost
only while the file is written. `write_png` draws block paths (top and side views)
and the speed of every moved block over time with matplotlib.
"""
from __future__ import annotations

from pathlib import Path

from lgp.paper import DISPLAY_RGB as COLOURS


def write_html(plan, path) -> str:
    """Write a self-contained replay of `plan` (an lgp.planner.Plan) to `path`."""
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
    meshcat = Meshcat()
    MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat, MeshcatVisualizerParams(role=Role.kIllustration, prefix="arm"))
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyContextFromRoot(context)

    meshcat.SetObject("/table", Box(1.2, 1.2, 0.02), Rgba(0.75, 0.75, 0.72, 1.0))
    meshcat.SetTransform("/table", RigidTransform([0.42, 0.0, -0.01]))
    for i, box in enumerate(plan.initial.fixed):
        meshcat.SetObject(f"/fixed/{box.name}_{i}", Box(*box.size), Rgba(0.45, 0.45, 0.5, 0.6))
        meshcat.SetTransform(f"/fixed/{box.name}_{i}", RigidTransform(box.p_WO))
    for b in plan.target.blocks:  # ghost of the target
        meshcat.SetObject(f"/target/{b.name}", Box(*b.size), Rgba(*COLOURS.get(b.colour, (0.5, 0.5, 0.5)), 0.2))
        meshcat.SetTransform(f"/target/{b.name}", b.X_WB)
    for b in plan.initial.blocks:
        meshcat.SetObject(f"/blocks/{b.name}", Box(*b.size), Rgba(*COLOURS.get(b.colour, (0.5, 0.5, 0.5)), 1.0))

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
    path = Path(path)
    path.write_text(meshcat.StaticHtml())
    return str(path)


def write_png(plan, path) -> str:
    """Write a figure of block paths (top view x-y, side view x-z) and speeds to `path`."""
    import matplotlib

    from models.effort import kinetic_energy

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    moved = plan.symbolic.moved
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6))
    top, side, speed = axes
    for b in plan.initial.blocks:
        c = COLOURS.get(b.colour, (0.5, 0.5, 0.5))
        p = plan.p_WB[b.name]
        edge = "k" if b.name in moved else (0.6, 0.6, 0.6)
        top.plot(p[:, 1], p[:, 0], color=c, lw=1.5)
        side.plot(p[:, 0], p[:, 2], color=c, lw=1.5)
        top.scatter(p[0, 1], p[0, 0], color=c, edgecolor=edge, marker="s", s=30, zorder=3)
        top.scatter(p[-1, 1], p[-1, 0], color=c, edgecolor=edge, marker="o", s=30, zorder=3)
        if b.name in moved:
            speed.plot(plan.t, plan.speed(b.name), color=c, lw=1.2, label=b.name)
    for box in plan.initial.fixed:
        x0, y0 = box.p_WO[0] - box.size[0] / 2, box.p_WO[1] - box.size[1] / 2
        top.add_patch(plt.Rectangle((y0, x0), box.size[1], box.size[0], color="0.6", alpha=0.5))
    top.set(xlabel="y (m, left +)", ylabel="x (m, away from the agent)", title="block paths, top view (square: start, dot: end)")
    top.invert_xaxis()
    top.set_aspect("equal")
    side.set(xlabel="x (m)", ylabel="z (m)", title="side view")
    side.set_aspect("equal")
    speed.set(xlabel="time (s)", ylabel="block speed (m/s)",
              title=f"speeds; effort {kinetic_energy(plan):.3f} J s, {len(plan.actions)} actions")
    if len(moved) <= 12:
        speed.legend(fontsize=7, ncol=2)
    label = f"{plan.initial.label} -> {plan.target.label}"
    fig.suptitle(label)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return str(path)
