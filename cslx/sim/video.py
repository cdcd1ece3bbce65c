"""Rendered video of a robot pass along a weld, and the true weld line in the robot frame."""

from __future__ import annotations

import math

import numpy as np

from ..sensor import Sensor, default_sensor
from .render import (
    _nuisance,
    _stack_gt,
    _with_laser,
    make_world,
    render_frame,
)
from .scene import (
    RobotPose,
)
from .shade import (
    Nuisance,
)
from .truth import true_weld_line

# ----------------------------------------------------------------------------- video


def video_path(n_frames, speed, fps, turn_radius, lookahead, turn_sign, rng):
    """Poses of a look-ahead point driving along the stem (−x_w → J) and turning onto the bar.

    The nominal path runs along y = 0 towards x = −turn_radius, follows a quarter circle
    onto the line x = 0 (the bar) and continues along it; a lateral wobble and a heading
    wobble are added. Returns (look-ahead xy (F, 2), heading (F,), on_bar (F,) bool).
    """
    L = n_frames * speed / fps
    arc = 0.5 * math.pi * turn_radius
    # s = 0 where the arc starts; the arc's middle is at mid-video.
    s = np.arange(n_frames) * speed / fps - 0.5 * L + 0.5 * arc
    xy = np.zeros((n_frames, 2))
    tang = np.zeros(n_frames)
    for i, si in enumerate(s):
        if si < 0:
            xy[i] = (-turn_radius + si, 0.0)
            tang[i] = 0.0
        elif si < arc:
            a = si / turn_radius
            xy[i] = (
                -turn_radius + turn_radius * math.sin(a),
                turn_sign * turn_radius * (1 - math.cos(a)),
            )
            tang[i] = turn_sign * a
        else:
            xy[i] = (0.0, turn_sign * (turn_radius + si - arc))
            tang[i] = turn_sign * math.pi / 2
    phase = rng.uniform(0, 2 * np.pi, 2)
    wobble = 4.0 * np.sin(2 * np.pi * s / 170.0 + phase[0])
    normal = np.stack([-np.sin(tang), np.cos(tang)], 1)
    xy = xy + wobble[:, None] * normal
    heading = tang + np.deg2rad(2.5) * np.sin(2 * np.pi * s / 230.0 + phase[1])
    return xy, heading, s > 0.5 * arc


def render_video(
    sensor: Sensor | None = None,
    n_frames: int = 200,
    seed: int = 0,
    nuisance: str | Nuisance = "clean",
    speed_mm_s: float = 30.0,
    fps: float = 20.0,
    *,
    progress: bool = False,
    laser: str | tuple[float, float, float] | None = None,
    power: float | None = None,
) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray, dict[str, np.ndarray]]:
    """A robot drives along a weld towards a T-intersection and turns onto the crossing weld.

    The look-ahead point (where the horizontal stripe meets the wall) follows the stem, turns
    on a 60 mm quarter circle at the junction and follows the bar, with a ±4 mm lateral and
    ±2.5° heading wobble; the robot moves `speed_mm_s / fps` mm per frame. The sun and
    shadow stay fixed (relative to the robot) over the video; noise changes per frame.

    Returns:
        frames (F, H, W, 3) uint8; gt (the per-frame ground truth of `render_frame`, stacked,
        plus `t_s` and `followed`); poses (F, 6) as `RobotPose` fields; lines: per frame
        `offset_mm`, `heading_deg`, `junction_x_mm`, `followed` (index of the weld followed)
        and the world's weld centre lines `weld_points` (K, 2), `weld_dirs` (K, 2).
    """
    sensor = sensor or default_sensor()
    rng = np.random.default_rng([seed, 999])
    w0, h0 = rng.uniform(12, 22), rng.uniform(1.5, 3)
    w1, h1 = rng.uniform(12, 22), rng.uniform(1.5, 3)
    world = make_world(
        [((0.0, 0.0), math.pi, w0, h0, True), ((0.0, 0.0), math.pi / 2, w1, h1, False)],
        rng=rng,
    )
    turn_sign = float(rng.choice([-1, 1]))
    lookahead = float(np.asarray(sensor.T_cr)[0])
    xy, heading, on_bar = video_path(n_frames, speed_mm_s, fps, 60.0, lookahead, turn_sign, rng)
    nz = _with_laser(_nuisance(nuisance, rng), laser, power)
    frames, gts, poses = [], [], []
    it = range(n_frames)
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc="render video")
    for i in it:
        ref = xy[i] - lookahead * np.array([math.cos(heading[i]), math.sin(heading[i])])
        pose = RobotPose(float(ref[0]), float(ref[1]), float(heading[i]))
        img, gt = render_frame(sensor, world, pose, nz, seed=seed * 100003 + i, scene_seed=seed)
        follow, crossing = (1, -1) if on_bar[i] else (0, 1)
        gt.update(
            {
                k: np.asarray(v, float)
                for k, v in true_weld_line(world, pose, sensor, follow, crossing).items()
            }
        )
        gt["followed"] = np.asarray(follow)
        gt["t_s"] = np.asarray(i / fps)
        frames.append(img)
        gts.append(gt)
        poses.append(np.asarray(pose, float))
    gt = _stack_gt(gts)
    lines = dict(
        offset_mm=gt["offset_mm"],
        heading_deg=gt["heading_deg"],
        junction_x_mm=gt["junction_x_mm"],
        followed=gt["followed"],
        weld_points=np.asarray(world.points, float),
        weld_dirs=np.asarray(world.dirs, float),
        weld_widths=np.asarray(world.widths, float),
        weld_heights=np.asarray(world.heights, float),
    )
    return np.stack(frames), gt, np.stack(poses), lines
