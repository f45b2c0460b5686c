"""Plane geometry written once (lgp.geometry): the separating-axis depth is the
shortest push that separates two outlines, rotations match Drake's, and the
fingerprint sees every bit."""
from __future__ import annotations

import numpy as np
import pytest
from pydrake.math import RotationMatrix

from lgp.geometry import clip_convex, digest, polygon_area, quaternion_from_yaw, rectangle, rectangle_overlap, yaw_direction


def shared_area(c_a, size_a, yaw_a, c_b, size_b, yaw_b) -> float:
    P = clip_convex(rectangle(c_a, size_a, yaw_a), rectangle(c_b, size_b, yaw_b))
    return abs(polygon_area(P)) if len(P) >= 3 else 0.0


def test_overlap_depth_is_the_shortest_push_that_separates_by_brute_force_over_directions():
    rng = np.random.default_rng(0)
    directions = yaw_direction(np.linspace(0, 2 * np.pi, 360, endpoint=False))
    checked = 0
    while checked < 20:
        size_a, size_b = rng.uniform(0.02, 0.06, 2), rng.uniform(0.02, 0.06, 2)
        yaw_a, yaw_b = rng.uniform(0, np.pi, 2)
        c_a, c_b = np.zeros(2), rng.uniform(-0.04, 0.04, 2)
        depth, normal = rectangle_overlap(c_a[None], size_a[None] / 2, yaw_direction([yaw_a]), c_b[None], size_b[None] / 2,
                                          yaw_direction([yaw_b]))
        depth, normal = float(depth[0]), normal[0]
        area = shared_area(c_a, size_a, yaw_a, c_b, size_b, yaw_b)
        if depth <= 0:
            assert area < 1e-12  # apart by the separating axis: nothing shared
            continue
        assert area > 0
        # pushing b along the normal by the depth separates them ...
        assert shared_area(c_a, size_a, yaw_a, c_b + normal * (depth + 1e-9), size_b, yaw_b) < 1e-12
        # ... and no direction separates them with a shorter push
        for w in directions:
            assert shared_area(c_a, size_a, yaw_a, c_b + w * depth * 0.999, size_b, yaw_b) > 0
        checked += 1


def test_clipped_squares_share_the_closed_form_octagon():
    d = 0.04
    P = clip_convex(rectangle([0, 0], [d, d], 0.0), rectangle([0, 0], [d, d], np.pi / 4))
    assert len(P) == 8 and abs(polygon_area(P)) == pytest.approx(2 * (np.sqrt(2) - 1) * d * d, rel=1e-12)


def test_quaternion_from_yaw_is_drakes_rotation_about_z():
    yaw = np.linspace(-3.0, 3.0, 13)
    for y, q in zip(yaw, quaternion_from_yaw(yaw)):
        expected = RotationMatrix.MakeZRotation(y).ToQuaternion().wxyz()
        assert np.allclose(q, expected, atol=1e-15)


def test_digest_sees_one_ulp_and_the_order_of_parts():
    p = np.array([0.35, 0.0, 0.02])
    assert digest("b1", p) == digest(b"b1", p.copy())
    assert digest("b1", p) != digest("b1", np.nextafter(p, 1.0))
    assert digest("b1", p) != digest(p, "b1")
