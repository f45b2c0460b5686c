"""Pictures of the trials as photographs of wooden blocks on a table: Start (A) and
Finish (B), rendered by Drake's RenderEngineVtk (``python -m stimuli.render``,
stimuli/render/__main__.py).

One idea a module:

- `camera`: the pinhole Camera, the corners of a scene, the one camera fitted to
  every scene of a run (`fit_camera`), the pictures' size (DEFAULT_SIZE, `parse_size`);
- `engine`: the block and table textures and the `Renderer` (RenderEngineVtk, lights,
  shadows, ambient occlusion);
- `run`: the pictures of a set of trials (`pictures_of`), the cached render run
  (`render_trials`, renders.json), the render cache's folders and a contact sheet.
"""
from __future__ import annotations

from stimuli.render.camera import (DEFAULT_SIZE, ELEVATION_DEG, FOV_Y_DEG, MARGIN, WORKSPACE_HI, WORKSPACE_LO, Camera,
                                   fit_camera, parse_size, scene_corners)
from stimuli.render.engine import BACKGROUND_RGB, FIXED_RGB, SEAM, TABLE_RGB, TEXTURE_GAMMA, Renderer
from stimuli.render.run import PROG, cache_folder, contact_sheet, pictures_of, render_cache_dir, render_trials

__all__ = ["BACKGROUND_RGB", "DEFAULT_SIZE", "ELEVATION_DEG", "FIXED_RGB", "FOV_Y_DEG", "MARGIN", "PROG", "SEAM",
           "TABLE_RGB", "TEXTURE_GAMMA", "WORKSPACE_HI", "WORKSPACE_LO", "Camera", "Renderer", "cache_folder",
           "contact_sheet", "fit_camera", "parse_size", "pictures_of", "render_cache_dir", "render_trials",
           "scene_corners"]
