"""Pictures of the trials as photographs of wooden blocks on a table: Start (A) and
Finish (B), rendered by Drake's RenderEngineVtk (``python -m stimuli.render``,
stimuli/render/__main__.py).

One idea a module:

- `camera`: the pinhole Camera, the corners of a scene, the oblique camera of a
  trial fitted to its A and B (`trial_camera`, `fit_camera`), the pictures' size
  (DEFAULT_SIZE, `parse_size`);
- `engine`: the block and table textures and the `Renderer` (RenderEngineVtk, lights,
  shadows, ambient occlusion);
- `run`: the pictures of a set of trials (`pictures_of`, which layout of A: `layout_sample`), the cached render run
  (`render_trials`, renders.json), the render cache's folders and a contact sheet.
"""
from __future__ import annotations

from stimuli.render.camera import (AZIMUTH_DEG, DEFAULT_SIZE, ELEVATION_DEG, FOV_Y_DEG, MARGIN, MIN_AREA, WORKSPACE_HI,
                                   WORKSPACE_LO, Camera, fit_camera, parse_size, scene_corners, trial_camera, view_direction)
from stimuli.render.engine import BACKGROUND_RGB, FIXED_RGB, SEAM, TABLE_RGB, TEXTURE_GAMMA, Renderer
from stimuli.render.run import (LAYOUTS, PROG, cache_folder, contact_sheet, layout_sample, pictures_of, picture_store,
                                render_cache_dir, render_trials)

__all__ = ["AZIMUTH_DEG", "BACKGROUND_RGB", "DEFAULT_SIZE", "ELEVATION_DEG", "FIXED_RGB", "FOV_Y_DEG", "LAYOUTS", "MARGIN",
           "MIN_AREA", "PROG", "SEAM", "TABLE_RGB", "TEXTURE_GAMMA", "WORKSPACE_HI", "WORKSPACE_LO", "Camera", "Renderer",
           "cache_folder", "contact_sheet", "fit_camera", "layout_sample", "parse_size", "pictures_of", "picture_store", "render_cache_dir",
           "render_trials", "scene_corners", "trial_camera", "view_direction"]
