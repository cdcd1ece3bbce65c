"""The tracking truth: the followed weld line, its bead and the T-junction in the robot frame."""

from __future__ import annotations

import numpy as np

from ..sensor import Sensor, default_sensor
from .scene import RobotPose, World


def _plane_in_robot(sensor: Sensor, i: int) -> tuple[np.ndarray, float]:
    """Plane i as n_r·X_r + d_r = 0 in the robot frame."""
    n = np.asarray(sensor.planes, float)[i]
    R = np.asarray(sensor.R_cr, float)
    T = np.asarray(sensor.T_cr, float)
    n_r = R @ n
    return n_r, 1.0 - n_r @ T


def _welds_in_robot(world: World, pose: RobotPose):
    p = np.asarray(pose, float)
    from .scene import _np_rot_x, _np_rot_y, _np_rot_z

    R = _np_rot_z(p[2]) @ _np_rot_y(p[5]) @ _np_rot_x(p[4])
    t = np.array([p[0], p[1], p[3]])
    pts = np.asarray(world.points, float)
    dirs = np.asarray(world.dirs, float)
    P = (np.concatenate([pts, np.zeros((len(pts), 1))], 1) - t) @ R
    D = np.concatenate([dirs, np.zeros((len(pts), 1))], 1) @ R
    return P, D


def true_weld_line(
    world: World, pose: RobotPose, sensor: Sensor | None = None, follow: int = 0, crossing: int = 1
) -> dict[str, float]:
    """Tracking ground truth in the robot frame (docs/contracts.md, "Tracking log").

    The followed weld's centre line (on the wall, z_w = 0) meets laser plane 0 at one point:
    `offset_mm` is its y_r (positive: weld to the robot's left) and `stripe_x_mm` its x_r;
    `heading_deg` is the weld's direction in the x_r–y_r plane relative to x_r
    (counter-clockwise positive, in (−90°, 90°]); `junction_x_mm` is the x_r where the
    crossing weld's centre line meets plane 1 (the vertical stripe), NaN without one.
    `bead_width_mm`, `bead_height_mm` describe the followed weld.
    """
    sensor = sensor or default_sensor()
    P, D = _welds_in_robot(world, pose)
    heights = np.asarray(world.heights, float)
    widths = np.asarray(world.widths, float)

    def meet(k, i):
        n_r, d_r = _plane_in_robot(sensor, i)
        den = n_r @ D[k]
        if abs(den) < 1e-12:
            return np.full(3, np.nan)
        return P[k] - D[k] * (n_r @ P[k] + d_r) / den

    X = meet(follow, 0)
    dx, dy = D[follow, 0], D[follow, 1]
    if dx < 0 or (dx == 0 and dy < 0):
        dx, dy = -dx, -dy
    junction = np.nan
    if 0 <= crossing < len(heights) and heights[crossing] > 0 and crossing != follow:
        junction = float(meet(crossing, 1)[0])
    return dict(
        offset_mm=float(X[1]),
        stripe_x_mm=float(X[0]),
        heading_deg=float(np.degrees(np.arctan2(dy, dx))),
        junction_x_mm=junction,
        bead_width_mm=float(widths[follow]),
        bead_height_mm=float(heights[follow]),
    )
