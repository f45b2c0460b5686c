"""The renderer of the trials' pictures: Drake's RenderEngineVtk (VTK, OpenGL offscreen
on the CPU; Drake is already a dependency) with the table, directional lights clustered
around one direction, each casting a shadow map (their overlap gives soft penumbrae),
ambient occlusion for the contact shadows under blocks, and a wood-grain texture with
darkened edges per block colour so that touching blocks show their seams."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from lgp.paper import DISPLAY_RGB
from stimuli.render.camera import Camera

#: Each rendered block is this much (m) smaller than its cube so touching blocks show a seam.
SEAM = 0.0006
#: Colour of the fixed boxes (pair 12's bucket): grey-blue plastic.
FIXED_RGB = (0.45, 0.50, 0.58)
TABLE_RGB = (0.80, 0.78, 0.74)
#: Behind the table: the colour the lit table takes far from the camera (measured on
#: a render), so that where the oblique view reaches past the table's edge no edge shows.
BACKGROUND_RGB = (0.659, 0.639, 0.608)
#: Side of the table (m): most oblique pictures end on it; a larger one spreads the
#: shadow maps over more table and blurs the blocks' shadows.
TABLE_SIZE = 3.0


def _texture(colour: str, n: int = 128) -> np.ndarray:
    """A face texture (n, n, 3) in 0..1: wood grain (stronger on natural wood than
    under paint) and edges darkened over 5 % of the face, like a sanded block's."""
    rng = np.random.default_rng(sum(map(ord, colour)))
    u = np.linspace(0, 1, n)[None, :]
    v = np.linspace(0, 1, n)[:, None]
    wobble = 0.25 * np.sin(2 * np.pi * (1.3 * v + 0.2)) + 0.05 * np.cumsum(rng.standard_normal((n, 1)), axis=0) / np.sqrt(n)
    grain = 0.5 + 0.5 * np.sin(2 * np.pi * (7 * u + wobble))
    k = 0.10 if colour == "natural" else 0.04
    shade = 1 - k / 2 + k * (grain - 0.5) + 0.025 * rng.standard_normal((n, n))
    edge = np.minimum(np.minimum(u, 1 - u), np.minimum(v, 1 - v))
    shade = shade * (1 - 0.28 * np.clip(1 - edge / 0.05, 0, 1) ** 2)
    return np.clip(np.asarray(DISPLAY_RGB[colour])[None, None, :] * shade[..., None], 0, 1)


def _table_texture(n: int = 512) -> np.ndarray:
    rng = np.random.default_rng(7)
    fine = rng.standard_normal((n, n))
    fine = (fine + np.roll(fine, 1, 0) + np.roll(fine, 1, 1) + np.roll(fine, (1, 1), (0, 1))) / 4
    return np.clip(np.asarray(TABLE_RGB)[None, None, :] * (1 + 0.018 * fine[..., None]), 0, 1)


#: VTK reads a texture as sRGB and writes the picture without converting back, so a
#: texture is stored with this gamma applied (1.5: dark colours keep their hue, light ones are not washed out; judged by eye).
TEXTURE_GAMMA = 1 / 1.5


def _write_png(path: Path, rgb: np.ndarray) -> None:
    from PIL import Image

    Image.fromarray((np.clip(rgb, 0, 1) ** TEXTURE_GAMMA * 255).round().astype(np.uint8)).save(path)


# ----------------------------------------------------------------------------- the engine


class Renderer:
    """One RenderEngineVtk with the table and lights, reused for every picture (its
    shaders are compiled once per process)."""

    def __init__(self, camera: Camera):
        from pydrake.geometry import (Box, ClippingRange, ColorRenderCamera, GeometryId, LightParameter,
                                      MakeRenderEngineVtk, RenderCameraCore, RenderEngineVtkParams, SsaoParameter)
        from pydrake.math import RigidTransform, RotationMatrix
        from pydrake.systems.sensors import CameraInfo

        self._Box, self._GeometryId, self._RigidTransform, self._RotationMatrix = Box, GeometryId, RigidTransform, RotationMatrix
        self._textures = tempfile.TemporaryDirectory(prefix="lgp-render-")
        tex = Path(self._textures.name)
        for colour in DISPLAY_RGB:
            _write_png(tex / f"{colour}.png", _texture(colour))
        _write_png(tex / "table.png", _table_texture())
        self._tex = tex
        key = np.array([0.25, 0.30, -1.0])  # the key light: high above, a little behind and right of the agent
        lights = [LightParameter(type="directional", direction=(key + np.array(j)).tolist(), intensity=0.15, frame="world")
                  for j in ((0.025, 0.025, 0), (-0.025, 0.025, 0), (0.025, -0.025, 0), (-0.025, -0.025, 0))]
        # Fill from the camera: its shadows lie behind the blocks, out of sight.
        lights.append(LightParameter(type="directional", direction=[0.0, 0.0, 1.0], intensity=0.56, frame="camera"))
        # Small pictures (the page's cards, tests) need no finer shadow map nor more AO
        # samples to look the same, and render about 3 times faster with these.
        small = max(camera.width, camera.height) <= 640
        params = RenderEngineVtkParams(cast_shadows=True, shadow_map_size=1024 if small else 2048, lights=lights,
                                       default_clear_color=list(BACKGROUND_RGB),
                                       ssao=SsaoParameter(radius=0.03, bias=0.002, sample_count=16 if small else 32))
        self.engine = MakeRenderEngineVtk(params)
        self.camera = camera
        self.engine.RegisterVisual(GeometryId.get_new_id(), Box(TABLE_SIZE, TABLE_SIZE, 0.02), self._props(rgb=TABLE_RGB),
                                   RigidTransform([0.55, 0.0, -0.01]), False)
        core = RenderCameraCore("vtk", CameraInfo(camera.width, camera.height, np.radians(camera.fov_y_deg)),
                                ClippingRange(0.05, 2 * TABLE_SIZE), RigidTransform())
        self._cam = ColorRenderCamera(core, False)
        self.engine.UpdateViewpoint(RigidTransform(RotationMatrix(camera.rotation()), np.asarray(camera.eye)))

    def _props(self, texture: str | None = None, rgb=None):
        from pydrake.geometry import PerceptionProperties, RenderLabel, Rgba

        p = PerceptionProperties()
        if texture is not None:
            p.AddProperty("phong", "diffuse_map", str(self._tex / f"{texture}.png"))
        if rgb is not None:
            p.AddProperty("phong", "diffuse", Rgba(*rgb, 1.0))
        p.AddProperty("label", "id", RenderLabel(1))
        return p

    def render(self, scene, path: Path, camera: Camera | None = None) -> None:
        """Render `scene` (blocks and fixed boxes) to the PNG `path` (written atomically),
        seen from `camera` (of this renderer's size and field of view) if given."""
        from pydrake.systems.sensors import ImageRgba8U

        if camera is not None and camera != self.camera:
            if (camera.width, camera.height, camera.fov_y_deg) != (self.camera.width, self.camera.height, self.camera.fov_y_deg):
                from lgp.errors import InputError

                raise InputError(f"a camera of {camera.width}x{camera.height} px, fov {camera.fov_y_deg}: this renderer draws "
                                 f"{self.camera.width}x{self.camera.height} px, fov {self.camera.fov_y_deg}")
            self.engine.UpdateViewpoint(self._RigidTransform(self._RotationMatrix(camera.rotation()), np.asarray(camera.eye)))
            self.camera = camera
        ids = []
        try:
            for b in scene.blocks:
                g = self._GeometryId.get_new_id()
                size = np.maximum(np.asarray(b.size) - SEAM, 0.5 * np.asarray(b.size))
                self.engine.RegisterVisual(g, self._Box(*size), self._props(texture=b.colour),
                                           self._RigidTransform(self._RotationMatrix.MakeZRotation(b.yaw), b.p_WB), False)
                ids.append(g)
            for f in scene.fixed:
                g = self._GeometryId.get_new_id()
                self.engine.RegisterVisual(g, self._Box(*f.size), self._props(rgb=FIXED_RGB), self._RigidTransform(f.p_WO), False)
                ids.append(g)
            image = ImageRgba8U(self.camera.width, self.camera.height)
            self.engine.RenderColorImage(self._cam, image)
        finally:
            for g in ids:
                self.engine.RemoveGeometry(g)
        rgb = np.array(image.data)[:, :, :3]
        tmp = path.with_name(f".{path.name}.tmp.png")
        from PIL import Image

        Image.fromarray(rgb).save(tmp)
        os.replace(tmp, path)
