"""Tests of the scene renderer and its exact ground truth (`cslx.sim`).

References are independent of the root-finders: OpenCV's projection, the surface height
field evaluated directly, the plane equations, the analytic tracking truth, and OpenCV's
chessboard detector on the rendered calibration images.
"""

import filecmp
import os

import cv2
import equinox as eqx
import numpy as np
import pytest

from cslx import sim as synth
from cslx.sensor import default_sensor
from cslx.sim.scene import bead_profile, camera_to_world, fan_angle, surface_z

SENSOR = default_sensor()


@pytest.fixture(scope="module")
def cross_frame():
    rng = np.random.default_rng(7)
    world = synth.random_world("cross", rng)
    pose = synth.random_pose(world, "cross", rng, SENSOR)
    img, gt = synth.render_frame(SENSOR, world, pose, "clean", seed=3)
    return world, pose, img, gt


@pytest.fixture(scope="module")
def straight_frame():
    rng = np.random.default_rng(11)
    world = synth.random_world("straight", rng)
    pose = synth.random_pose(world, "straight", rng, SENSOR)
    img, gt = synth.render_frame(SENSOR, world, pose, "sunny", seed=4)
    return world, pose, img, gt


def _world_points(pose, X_c):
    R_wc, C_w = camera_to_world(SENSOR, synth.RobotPose(*[float(v) for v in pose]))
    return X_c @ np.asarray(R_wc, float).T + np.asarray(C_w, float)


def _check_self_consistent(world, pose, gt, key_px, key_xyz, plane):
    W, H = SENSOR.camera.image_size
    px, X = gt[key_px], gt[key_xyz]
    ok = np.isfinite(px)
    assert ok.sum() > 0.8 * len(px), "stripe mostly missing"
    X = X[ok]
    idx = np.arange(len(px))[ok]
    uv = np.stack([idx, px[ok]], 1) if plane == 0 else np.stack([px[ok], idx], 1)
    # 1. Projects back onto its pixel (OpenCV's projection, float64).
    K = np.asarray(SENSOR.camera.K, float)
    dist = np.asarray(SENSOR.camera.dist, float)
    proj, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), K, dist)
    assert np.max(np.abs(proj[:, 0] - uv)) < 1e-6
    # 2. Lies on the laser plane: distance |n·X + 1| / |n| in mm.
    n = np.asarray(SENSOR.planes, float)[plane]
    assert np.max(np.abs(X @ n + 1) / np.linalg.norm(n)) < 1e-6
    # 3. Lies on the surface z_w = S(x_w, y_w).
    Xw = _world_points(pose, X)
    world64 = synth.World(*[np.asarray(a, float) for a in world.__dict__.values()])
    S = np.asarray(surface_z(Xw[:, :2], world64))
    assert np.max(np.abs(Xw[:, 2] - S)) < 1e-6
    assert np.all((px[ok] >= -0.5) & (px[ok] <= (H if plane == 0 else W) - 0.5))
    return Xw, S


def test_ground_truth_on_pixel_plane_and_surface(cross_frame):
    world, pose, _, gt = cross_frame
    _check_self_consistent(world, pose, gt, "h_v", "h_xyz", 0)
    _check_self_consistent(world, pose, gt, "v_u", "v_xyz", 1)


def test_cross_scene_both_stripes_cross_a_bead(cross_frame):
    world, pose, img, gt = cross_frame
    heights = np.asarray(world.heights)
    Xw, S = _check_self_consistent(world, pose, gt, "h_v", "h_xyz", 0)
    # The horizontal stripe passes over the stem's apex: max height = bead height (0.01 mm:
    # columns sample the cap every ≈0.25 mm near its flat top).
    assert abs(S.max() - heights[0]) < 0.01
    # The vertical stripe runs along the stem (beside or on it) and over the bar's apex.
    Xw, S = _check_self_consistent(world, pose, gt, "v_u", "v_xyz", 1)
    assert S.max() >= heights[1] - 0.01
    assert S.max() <= max(heights[0], heights[1]) + 1e-9
    # And the stripes are really drawn: the GT rows are red-dominant in the image.
    u = np.arange(img.shape[1])
    ok = np.isfinite(gt["h_v"])
    on = img[np.round(gt["h_v"][ok]).astype(int), u[ok]].astype(int)
    assert np.median(on[:, 0] - on[:, 1]) > 60


def test_straight_stripe_bump_and_tracking_truth(straight_frame):
    world, pose, img, gt = straight_frame
    assert img.shape == (480, 640, 3) and img.dtype == np.uint8
    Xw, S = _check_self_consistent(world, pose, gt, "h_v", "h_xyz", 0)
    h = float(np.asarray(world.heights)[0])
    assert abs(S.max() - h) < 0.01
    # The bump is visible in the image: the stripe rows move by pixels over the bead.
    assert np.nanmax(gt["h_v"]) - np.nanmin(gt["h_v"]) > h * 0.8
    # Tracking truth vs the GT stripe point at the bead's apex, in the robot frame.
    ok = np.isfinite(gt["h_v"])
    X_r = np.asarray(SENSOR.to_robot(gt["h_xyz"][ok]))
    apex = X_r[np.argmax(S)]
    line = synth.true_weld_line(world, pose, SENSOR)
    assert abs(apex[1] - line["offset_mm"]) < 0.4
    # stripe_x is on the wall; plane 0 leans, so at the apex (height h) it lies ≈ h·tan(15–25°)
    # away along x_r.
    assert abs(apex[0] - line["stripe_x_mm"]) < 0.5 * h + 0.3
    # Heading: the weld's world angle minus the robot's heading (roll/pitch ≤ 2° change it
    # by well under 0.2°).
    d = np.asarray(world.dirs)[0]
    assert abs(line["heading_deg"] - (np.degrees(np.arctan2(d[1], d[0]) - pose.heading_rad))) < 0.2


def test_junction_truth_matches_vertical_stripe(cross_frame):
    world, pose, _, gt = cross_frame
    line = synth.true_weld_line(world, pose, SENSOR)
    assert np.isfinite(line["junction_x_mm"])
    ok = np.isfinite(gt["v_u"])
    Xw = _world_points(pose, gt["v_xyz"][ok])
    # The bar's apex along the vertical stripe: the point highest above the stem's cap.
    cap_bar = np.asarray(
        bead_profile(
            Xw[:, :2], synth.World(*[np.asarray(a, float) for a in world.__dict__.values()])
        )[0]
    )[:, 1]
    X_r = np.asarray(SENSOR.to_robot(gt["v_xyz"][ok]))
    assert abs(X_r[np.argmax(cap_bar), 0] - line["junction_x_mm"]) < 0.4


def test_nan_where_outside_fan():
    rng = np.random.default_rng(3)
    world = synth.random_world("straight", rng)
    pose = synth.random_pose(world, "straight", rng, SENSOR)
    full = synth.stripe_truth(SENSOR, world, pose, fan_half_deg=30.0)
    narrow = synth.stripe_truth(SENSOR, world, pose, fan_half_deg=10.0)
    ok = np.isfinite(full[0])
    theta = np.degrees(np.asarray(fan_angle(full[1][ok], SENSOR, 0)))
    inside = np.abs(theta) <= 10.0
    assert 0 < inside.sum() < ok.sum()
    assert np.array_equal(np.isfinite(narrow[0])[ok], inside)
    np.testing.assert_allclose(narrow[0][ok][inside], full[0][ok][inside], atol=1e-9)
    # Off the image: move the principal point so that the horizontal stripe (near the
    # image centre) projects below the last row; the vertical stripe stays in view.
    shifted = eqx.tree_at(lambda s: s.camera.v0, SENSOR, SENSOR.camera.v0 + 400.0)
    h_v, _, v_u, _ = synth.stripe_truth(shifted, world, pose)
    assert np.all(np.isnan(h_v))
    assert np.isfinite(v_u).sum() > 50


def test_render_is_deterministic():
    rng = np.random.default_rng(5)
    world = synth.random_world("cross", rng)
    pose = synth.random_pose(world, "cross", rng, SENSOR)
    a, ga = synth.render_frame(SENSOR, world, pose, "glare", seed=9)
    b, gb = synth.render_frame(SENSOR, world, pose, "glare", seed=9)
    c, _ = synth.render_frame(SENSOR, world, pose, "glare", seed=10)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    for k in ga:
        np.testing.assert_array_equal(ga[k], gb[k])


def test_laser_power_clips_core_to_white_and_green_laser():
    rng = np.random.default_rng(2)
    world = synth.random_world("straight", rng)
    pose = synth.random_pose(world, "straight", rng, SENSOR)
    nz = synth.Nuisance(laser_power=12000.0)
    img, gt = synth.render_frame(SENSOR, world, pose, nz, seed=1)
    u = np.arange(640)
    ok = np.isfinite(gt["h_v"])
    core = img[np.round(gt["h_v"][ok]).astype(int), u[ok]]
    assert np.mean(np.all(core == 255, axis=1)) > 0.5
    green = synth.Nuisance(laser_rgb=synth.LASER_RGB["green"])
    img, _ = synth.render_frame(SENSOR, world, pose, green, seed=1)
    core = img[np.round(gt["h_v"][ok]).astype(int), u[ok]].astype(int)
    assert np.median(core[:, 1] - core[:, 0]) > 60


def test_dataset_roundtrip_and_same_bytes(tmp_path):
    images, gt, sensor = synth.render_dataset("straight", "shadow", 2, seed=4)
    assert images.shape == (2, 480, 640, 3)
    assert gt["h_v"].shape == (2, 640) and gt["v_xyz"].shape == (2, 480, 3)
    names = synth.write_dataset(tmp_path / "a", images, gt, sensor)
    imgs2, gt2, sensor2 = synth.load_dataset(tmp_path / "a")
    assert np.array_equal(images, imgs2)
    for k in gt:
        np.testing.assert_array_equal(gt[k], gt2[k])
    assert list(gt2["frames"]) == names
    np.testing.assert_allclose(np.asarray(sensor2.planes), np.asarray(sensor.planes), rtol=1e-12)
    # The CLI writes identical bytes for identical arguments.
    from cslx.cli import main

    for d in ("c1", "c2"):
        assert (
            main(
                [
                    "render",
                    "--scene",
                    "cross",
                    "--frames",
                    "1",
                    "--seed",
                    "8",
                    "--out",
                    str(tmp_path / d),
                ]
            )
            == 0
        )
    files = sorted(os.listdir(tmp_path / "c1"))
    assert files == ["frame_00000.png", "gt.npz", "sensor.json"]
    match, mismatch, errors = filecmp.cmpfiles(
        tmp_path / "c1", tmp_path / "c2", files, shallow=False
    )
    assert mismatch == [] and errors == []
    with pytest.raises(FileNotFoundError, match="no such data set"):
        synth.load_dataset(tmp_path / "missing")


def test_calibration_board_corners_found_by_opencv():
    # Clean images (no sensor noise) for the sub-pixel accuracy check.
    clean = synth.Nuisance(ambient=170.0, texture=0.0, read_noise=0.0, electrons_per_dn=1e9)
    cal = synth.render_calibration(SENSOR, n_poses=2, seed=1, nuisance=clean)
    assert cal["plain"].shape == (2, 480, 640, 3) and cal["laser"].shape == (2, 480, 640, 3)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
    for i in range(2):
        gray = cv2.cvtColor(cal["plain"][i], cv2.COLOR_RGB2GRAY)
        found, corners = cv2.findChessboardCorners(gray, (10, 7))
        assert found
        corners = cv2.cornerSubPix(gray, corners, (8, 8), (-1, -1), crit).reshape(-1, 2)
        truth = cal["image_points"][i]
        if np.abs(corners[::-1] - truth).max() < np.abs(corners - truth).max():
            corners = corners[::-1]  # OpenCV may start from the opposite corner
        err = np.linalg.norm(corners - truth, axis=1)
        assert np.abs((corners - truth).mean(0)).max() < 0.02  # no pixel-convention bias
        assert np.sqrt(np.mean(err**2)) < 0.05 and err.max() < 0.1, err.max()
        # True pose reproduces the true corners through OpenCV's projection.
        proj, _ = cv2.projectPoints(
            cal["object_points"],
            cv2.Rodrigues(cal["R"][i])[0],
            cal["t"][i],
            np.asarray(SENSOR.camera.K, float),
            np.asarray(SENSOR.camera.dist, float),
        )
        np.testing.assert_allclose(proj[:, 0], truth, atol=1e-6)
        # Both stripes cross the board in the laser image (red minus green is high along
        # a horizontal and a vertical band).
        rg = cal["laser"][i][..., 0].astype(int) - cal["laser"][i][..., 1]
        assert (rg > 40).any(axis=1).sum() > 100 and (rg > 40).any(axis=0).sum() > 150


def test_video_path_turns_onto_the_crossing_weld():
    # Path only (no rendering): the look-ahead point follows the stem, then the bar.
    xy, heading, on_bar = synth.video_path(
        200, 30.0, 20.0, 60.0, 150.0, 1.0, np.random.default_rng(0)
    )
    step = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    assert np.all(np.abs(step - 1.5) < 0.3)  # 30 mm/s at 20 fps, plus the wobble
    assert not on_bar[0] and on_bar[-1]
    assert abs(np.degrees(heading[-1]) - 90) < 5 and abs(np.degrees(heading[0])) < 5
    frames, gt, poses, lines = synth.render_video(SENSOR, n_frames=2, seed=1)
    assert frames.shape == (2, 480, 640, 3) and poses.shape == (2, 6)
    assert np.all(np.isfinite(lines["offset_mm"])) and lines["followed"].shape == (2,)
    assert np.isfinite(gt["h_v"]).mean() > 0.8
