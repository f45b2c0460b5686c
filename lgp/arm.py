"""The planner's body: a 7-DOF arm with the KUKA LBR iiwa 14 kinematics and a gripper.

The model lives in ``models/arm.sdf`` (links, joint limits, gripper frame G); where it
is mounted and where it rests live in ``models/arm.yaml``. This module loads both
into a Drake MultibodyPlant and adds closed-form inverse kinematics.

Closed-form IK: the arm is spherical-rotational-spherical (joints 1-3 meet at the
shoulder S, joints 5-7 at the wrist W), so a gripper pose X_WG fixes W, the distance
|W - S| fixes joint 4, and the one redundant degree of freedom is the swivel angle
of the elbow about the line S-W. `ik_candidates` enumerates solutions over a grid
of swivel angles and the 8 shoulder/elbow/wrist branches; the planner picks among
them (lgp/planner/seeding.py) and KOMO refines them.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import yaml
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant

MODELS = Path(__file__).resolve().parent.parent / "models"
ARM_CONFIG = MODELS / "arm.yaml"

# Kinematic constants of models/arm.sdf (iiwa 14 R820), metres; checked against the
# parsed plant in tests/test_arm.py.
SHOULDER_HEIGHT = 0.36  # base frame origin to joint 2
UPPER_ARM = 0.42  # joint 2 to joint 4
FOREARM = 0.40  # joint 4 to joint 6
WRIST_TO_FLANGE = 0.126
FLANGE_TO_G = 0.10
WRIST_TO_G = WRIST_TO_FLANGE + FLANGE_TO_G


def _pose_from_yaml(data: dict) -> RigidTransform:
    rpy = np.radians(np.asarray(data.get("rpy_deg", [0.0, 0.0, 0.0]), float))
    return RigidTransform(RollPitchYaw(rpy), np.asarray(data["translation"], float))


@dataclass(frozen=True)
class ArmConfig:
    """Contents of models/arm.yaml: the model file, the base pose, the home posture."""

    model: Path
    X_WBase: RigidTransform
    q_home: np.ndarray

    @staticmethod
    def load(path: Path | str = ARM_CONFIG) -> "ArmConfig":
        path = Path(path)
        data = yaml.safe_load(path.read_text())
        return ArmConfig(
            model=(path.parent / data["model"]).resolve(),
            X_WBase=_pose_from_yaml(data["X_WBase"]),
            q_home=np.radians(np.asarray(data["q_home_deg"], float)),
        )


def add_arm(plant: MultibodyPlant, config: ArmConfig | None = None):
    """Parse the arm into `plant` and weld its base at X_WBase; returns the model instance."""
    config = config or ArmConfig.load()
    (instance,) = Parser(plant).AddModels(str(config.model))
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("iiwa_link_0", instance), config.X_WBase)
    return instance


class Arm:
    """A finalized plant holding only the arm, its gripper frame G and home posture.

    `plant` is a MultibodyPlant<double> (time step 0: kinematics only); `G` the
    gripper frame; `q_home` the rest posture where every plan starts and ends.
    """

    def __init__(self, config: ArmConfig | None = None):
        self.config = config or ArmConfig.load()
        self.plant = MultibodyPlant(time_step=0.0)
        self.instance = add_arm(self.plant, self.config)
        self.plant.Finalize()
        self.G = self.plant.GetFrameByName("G", self.instance)
        self.context = self.plant.CreateDefaultContext()
        self.q_home = self.config.q_home.copy()
        self.q_lower = self.plant.GetPositionLowerLimits()
        self.q_upper = self.plant.GetPositionUpperLimits()
        self.X_WBase = self.config.X_WBase

    @property
    def nq(self) -> int:
        return self.plant.num_positions()

    @cached_property
    def p_WS(self) -> np.ndarray:
        """The shoulder point S (joint 2 centre) in the world."""
        return self.X_WBase.multiply(np.array([0.0, 0.0, SHOULDER_HEIGHT]))

    def X_WG(self, q) -> RigidTransform:
        """Forward kinematics: pose of the gripper frame G in the world."""
        self.plant.SetPositions(self.context, np.asarray(q, float))
        return self.plant.CalcRelativeTransform(self.context, self.plant.world_frame(), self.G)

    def within_limits(self, q, margin: float = 0.0) -> np.ndarray:
        q = np.asarray(q, float)
        return np.all((q >= self.q_lower + margin) & (q <= self.q_upper - margin), axis=-1)

    def ik_candidates(self, X_WG: RigidTransform, swivels=None, margin: float = 0.0) -> np.ndarray:
        """Joint vectors (n, 7) placing G at X_WG exactly, within the joint limits.

        One per (swivel angle, branch) that respects the limits (shrunk by `margin`
        rad); empty (0, 7) when the pose is out of reach.
        """
        if swivels is None:
            swivels = np.linspace(-np.pi, np.pi, 24, endpoint=False)
        X_BG = self.X_WBase.inverse().multiply(X_WG)
        q = srs_ik(X_BG.rotation().matrix(), X_BG.translation(), np.asarray(swivels, float))
        return q[self.within_limits(q, margin)]

    def ik_from_above(self, p_WG, yaw: float, swivels, margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """IK for a vertical hand with G at p_WG and G's x axis at yaw + m * 90 deg, m = 0..3.

        Returns (q (n, 7), m (n,)): every solution within the limits and its quarter turn.
        """
        q, ok = self.ik_grid_from_above(p_WG, yaw, swivels, margin)
        labels = np.broadcast_to(np.arange(4)[:, None], ok.shape)
        return q[ok], labels[ok]

    def ik_grid_from_above(self, p_WG, yaw: float, swivels, margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """All IK solutions (4, 8 * len(swivels), 7) of `ik_from_above`, and which are within the limits.

        Row m is the quarter turn m; column i the same (branch, swivel) for every
        pose, so nearby poses give nearby solutions at the same index.
        """
        q, ok = self.ik_grids_from_above([(p_WG, yaw)], swivels, margin)
        return q[0], ok[0]

    def ik_grids_from_above(self, poses, swivels, margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """`ik_grid_from_above` for several (p_WG, yaw) at once: (P, 4, 8 * len(swivels), 7)
        solutions and (P, 4, 8 * len(swivels)) within the limits (none for a pose out of
        reach); one batched closed form (srs_ik_poses), the same numbers as pose by pose."""
        X_BW = self.X_WBase.inverse()
        R_BG = np.array([[X_BW.rotation().multiply(X_WG_from_above(p_WG, yaw + m * np.pi / 2).rotation()).matrix() for m in range(4)]
                         for p_WG, yaw in poses]).reshape(-1, 4, 3, 3)
        p_BG = np.array([X_BW.multiply(np.asarray(p_WG, float)) for p_WG, _ in poses]).reshape(-1, 3)
        q, reachable = srs_ik_poses(R_BG, p_BG, np.asarray(swivels, float))
        return q, self.within_limits(q, margin) & reachable[:, None, None]


# ----------------------------------------------------------------------------- closed-form IK


def _rot_z(a):
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(np.shape(a) + (3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 1, 0], R[..., 1, 1], R[..., 2, 2] = c, -s, s, c, 1.0
    return R


def _rot_y(a):
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(np.shape(a) + (3, 3))
    R[..., 0, 0], R[..., 0, 2], R[..., 2, 0], R[..., 2, 2], R[..., 1, 1] = c, s, -s, c, 1.0
    return R


def _axis_angle(u, a):
    """Rotation matrices (p, n, 3, 3) by angles a (n,) about the unit axes u (p, 3)."""
    u = np.asarray(u, float)
    K = np.zeros((len(u), 1, 3, 3))
    K[:, 0, 0, 1], K[:, 0, 0, 2], K[:, 0, 1, 0], K[:, 0, 1, 2], K[:, 0, 2, 0], K[:, 0, 2, 1] = -u[:, 2], u[:, 1], u[:, 2], -u[:, 0], -u[:, 1], u[:, 0]
    a = np.asarray(a)[..., None, None]
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * (K @ K)


def _zyz(R):
    """Both ZYZ Euler solutions (a, b, c) with R = Rz(a) Ry(b) Rz(c); arrays (2, n, 3)."""
    b = np.arccos(np.clip(R[..., 2, 2], -1.0, 1.0))
    a = np.arctan2(R[..., 1, 2], R[..., 0, 2])
    c = np.arctan2(R[..., 2, 1], -R[..., 2, 0])
    first = np.stack([a, b, c], axis=-1)
    wrap = lambda x: (x + np.pi) % (2 * np.pi) - np.pi  # noqa: E731
    second = np.stack([wrap(a + np.pi), -b, wrap(c + np.pi)], axis=-1)
    return np.stack([first, second])


def srs_ik(R_BG: np.ndarray, p_BG: np.ndarray, swivels: np.ndarray) -> np.ndarray:
    """All IK solutions of the arm for gripper poses in the base frame, ignoring limits.

    `R_BG` is one rotation (3, 3) or several (m, 3, 3) sharing their z axis (e.g. the
    four quarter turns of a vertical hand), all with G at `p_BG`; the wrist point is
    then common and only joints 5-7 differ. Returns (8 * len(swivels), 7) for one
    rotation, (m, 8 * len(swivels), 7) for several; no rows when out of reach.
    Joint axes of models/arm.sdf: z, y, z, -y, z, y, z; at q = 0 the arm is straight up.
    (One pose of `srs_ik_poses`.)
    """
    R_BG = np.asarray(R_BG, float)
    single = R_BG.ndim == 2
    R_BG = R_BG.reshape(-1, 3, 3)
    q, reachable = srs_ik_poses(R_BG[None], np.asarray(p_BG, float)[None], swivels)
    out = q[0] if reachable[0] else np.zeros((len(R_BG), 0, 7))
    return out[0] if single else out


def srs_ik_poses(R_BG: np.ndarray, p_BG: np.ndarray, swivels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`srs_ik` for P poses at once: R_BG (P, m, 3, 3) (per pose, m rotations sharing
    their z axis), p_BG (P, 3). Returns (q (P, m, 8 * len(swivels), 7), reachable (P,));
    the rows of an unreachable pose are zeros.

    The same arithmetic, operation by operation, as one pose at a time (the
    per-pose scalars in a loop, the swivel arrays with a leading pose axis), so the
    solutions are the same to the bit (tests/test_arm.py).
    """
    R_BG = np.asarray(R_BG, float)
    p_BG = np.asarray(p_BG, float).reshape(-1, 3)
    P, m = R_BG.shape[:2]
    swivels = np.asarray(swivels, float)
    n = len(swivels)
    a, b = UPPER_ARM, FOREARM
    p_BS = np.array([0.0, 0.0, SHOULDER_HEIGHT])
    out = np.zeros((P, m, 8 * n, 7))
    reachable = np.zeros(P, bool)
    scalars = []  # per reachable pose: (index, w / d, [(q4, phi, theta) for both elbows])
    for i in range(P):
        w = p_BG[i] - WRIST_TO_G * R_BG[i, 0, :, 2] - p_BS  # shoulder to wrist
        d = np.linalg.norm(w)
        cos4 = (d * d - a * a - b * b) / (2 * a * b)
        if abs(cos4) > 1.0:
            continue
        reachable[i] = True
        elbows = []
        for q4 in (np.arccos(cos4), -np.arccos(cos4)):
            # Shoulder to wrist in frame 3 (joint 4 turns about -y): v4 = a e_z + b Ry(-q4) e_z.
            v4 = np.array([-b * np.sin(q4), 0.0, a + b * np.cos(q4)])
            # A reference shoulder rotation with joint 3 at zero: Rz(phi) Ry(theta) v4 = w.
            phi = np.arctan2(w[1], w[0])
            theta = np.arctan2(np.hypot(w[0], w[1]), w[2]) - np.arctan2(v4[0], v4[2])
            elbows.append((q4, phi, theta))
        scalars.append((i, w / d, elbows))
    if not scalars:
        return out, reachable
    index = np.array([s[0] for s in scalars])
    R = R_BG[index]  # (p, m, 3, 3)
    p = len(index)
    swivel_circle = _axis_angle(np.array([s[1] for s in scalars]), swivels)  # (p, n, 3, 3)
    columns = []
    for e in range(2):
        q4 = np.array([s[2][e][0] for s in scalars])
        phi = np.array([s[2][e][1] for s in scalars])
        theta = np.array([s[2][e][2] for s in scalars])
        R_03 = swivel_circle @ (_rot_z(phi) @ _rot_y(theta))[:, None]  # every elbow on the swivel circle
        for q123 in _zyz(R_03):  # (p, n, 3)
            R_04 = _rot_z(q123[..., 0]) @ _rot_y(q123[..., 1]) @ _rot_z(q123[..., 2]) @ _rot_y(-q4)[:, None]
            R_47 = np.swapaxes(R_04, -1, -2)[:, None] @ R[:, :, None]  # (p, m, n, 3, 3)
            for q567 in _zyz(R_47):
                q = np.concatenate([np.broadcast_to(q123[:, None], (p, m, n, 3)),
                                    np.broadcast_to(q4[:, None, None, None], (p, m, n, 1)), q567], axis=3)
                columns.append(q)
    out[index] = np.concatenate(columns, axis=2)
    return out, reachable


def X_WG_from_above(p_WQ, yaw: float) -> RigidTransform:
    """Gripper pose with G at p_WQ, hand vertical (G z down) and G x at `yaw` about W z."""
    R = RotationMatrix.MakeZRotation(yaw).multiply(RotationMatrix.MakeXRotation(np.pi))
    return RigidTransform(R, np.asarray(p_WQ, float))
