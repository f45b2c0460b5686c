"""The camera of the trials' pictures: a pinhole camera of fixed direction, oblique
as a photograph taken standing at the table (ELEVATION_DEG above the table,
AZIMUTH_DEG round from the agent's side), fitted to both scenes of a trial, A and B,
so that Start and Finish are seen from the same place (`fit_camera`,
`trial_camera`); and the pictures' size (DEFAULT_SIZE, `parse_size` for --size)."""
from __future__ import annotations

import argparse
from dataclasses import dataclass

import numpy as np

#: Picture size (pixels) unless --size says otherwise.
DEFAULT_SIZE = (960, 640)
#: Vertical field of view of the camera (degrees) and its elevation above the table:
#: low enough that a tower's height shows (a vertical edge is drawn at cos 28 deg =
#: 0.88 of its length, against 0.67 at the 48 degrees of the first pictures).
FOV_Y_DEG = 36.0
ELEVATION_DEG = 28.0
#: The camera's direction round the vertical, from the agent's side (-x) towards -y
#: (degrees): offsets in x (the staircase of 4H, the lean of 10H) and in y (the row
#: of 7E) both show in the picture; seen straight from -x an x offset would not.
AZIMUTH_DEG = 40.0
#: The table area the camera of `fit_camera(..., area=WORKSPACE)` frames at least (x, y
#: in metres: the footprint of every scene of the 24 trials lies inside). The trials'
#: pictures frame their own scenes (`trial_camera`), with at least MIN_AREA around them.
WORKSPACE_LO = np.array([0.15, -0.30, 0.0])
WORKSPACE_HI = np.array([0.70, 0.32, 0.0])
#: Side (m) of the table square, centred on a trial's blocks, that its camera frames at
#: least: a trial of one or two blocks is not blown up beyond the others.
MIN_AREA = 0.24
#: Fraction of the picture left free at each side.
MARGIN = 0.04


@dataclass(frozen=True)
class Camera:
    """A pinhole camera: pose (eye, target, world up z) and vertical field of view."""

    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    fov_y_deg: float
    width: int
    height: int

    def rotation(self) -> np.ndarray:
        """R_WC: columns are the camera's x (right), y (down), z (forward) in W."""
        z = np.subtract(self.target, self.eye)
        z = z / np.linalg.norm(z)
        x = np.cross(z, [0.0, 0.0, 1.0])
        x = x / np.linalg.norm(x)
        return np.column_stack([x, np.cross(z, x), z])

    def project(self, P: np.ndarray) -> np.ndarray:
        """Pixel coordinates (u right, v down) of world points P (n, 3)."""
        R = self.rotation()
        p_C = (np.asarray(P, float) - np.asarray(self.eye)) @ R
        f = 0.5 * self.height / np.tan(np.radians(self.fov_y_deg) / 2)
        return np.column_stack([self.width / 2 + f * p_C[:, 0] / p_C[:, 2], self.height / 2 + f * p_C[:, 1] / p_C[:, 2]])

    def as_dict(self) -> dict:
        return {"eye": [round(v, 6) for v in self.eye], "target": [round(v, 6) for v in self.target],
                "fov_y_deg": self.fov_y_deg, "width": self.width, "height": self.height,
                "frame": "world W: table top z = 0, x away from the agent, y to its left"}


def scene_corners(scene) -> np.ndarray:
    """The 8 corners of every block and fixed box of a scene (n, 3)."""
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    out = []
    for b in scene.blocks:
        c, s = np.cos(b.yaw), np.sin(b.yaw)
        R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        out.append((signs * np.asarray(b.size) / 2) @ R.T + b.p_WB)
    for f in scene.fixed:
        out.append(signs * np.asarray(f.size) / 2 + f.p_WO)
    return np.vstack(out) if out else np.zeros((0, 3))


def view_direction() -> np.ndarray:
    """Unit vector from the camera's target towards its eye (ELEVATION_DEG, AZIMUTH_DEG)."""
    e, a = np.radians(ELEVATION_DEG), np.radians(AZIMUTH_DEG)
    return np.array([-np.cos(e) * np.cos(a), -np.cos(e) * np.sin(a), np.sin(e)])


def fit_camera(points: np.ndarray, width: int, height: int, area: tuple | None = None) -> Camera:
    """The camera of fixed direction (`view_direction`) that frames `points` and the
    table rectangle `area` = (lo, hi) (x, y corners at z = 0; none: the points alone)
    with MARGIN to spare: the target is moved until the points' projection is
    centred, the distance until it fills the picture."""
    P = np.asarray(points, float).reshape(-1, 3)
    if area is not None:
        lo, hi = area
        P = np.vstack([P, [[x, y, 0.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])]])
    back = view_direction()  # from target towards the eye
    target = np.array([(P[:, 0].min() + P[:, 0].max()) / 2, (P[:, 1].min() + P[:, 1].max()) / 2, 0.0])
    dist = 1.0
    for _ in range(40):
        cam = Camera(tuple(target + dist * back), tuple(target), FOV_Y_DEG, width, height)
        uv = cam.project(P)
        lo, hi = uv.min(axis=0), uv.max(axis=0)
        # Shift the target by the offset of the projection's centre (right, down in W).
        R = cam.rotation()
        f = 0.5 * height / np.tan(np.radians(FOV_Y_DEG) / 2)
        du, dv = (lo + hi) / 2 - (width / 2, height / 2)
        target = target + dist * (du / f * R[:, 0] + dv / f * R[:, 1])
        target[2] = 0.0
        fill = max((hi[0] - lo[0]) / (width * (1 - 2 * MARGIN)), (hi[1] - lo[1]) / (height * (1 - 2 * MARGIN)))
        dist *= fill ** 0.8
    cam = Camera(tuple(float(v) for v in target + dist * back), tuple(float(v) for v in target), FOV_Y_DEG, width, height)
    return cam


def trial_camera(scenes, width: int, height: int) -> Camera:
    """The one camera of a trial's pictures (A and B): `fit_camera` to the corners of
    both scenes and a table square of side MIN_AREA centred on their footprint."""
    P = np.vstack([scene_corners(s) for s in scenes])
    centre = (P[:, :2].min(axis=0) + P[:, :2].max(axis=0)) / 2
    return fit_camera(P, width, height, area=(centre - MIN_AREA / 2, centre + MIN_AREA / 2))


def parse_size(text: str) -> tuple[int, int]:
    """WIDTHxHEIGHT in pixels, each 64..4096."""
    try:
        w, h = (int(v, 10) for v in str(text).lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT in pixels such as 960x640, got {text!r}") from None
    if not (64 <= w <= 4096 and 64 <= h <= 4096):
        raise argparse.ArgumentTypeError(f"width and height must be 64..4096 pixels, got {text!r}")
    return w, h
