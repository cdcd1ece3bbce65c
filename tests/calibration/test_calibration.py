"""Calibration (paper section 2.3): OpenCV / Bouguet agreement, round trips, planes, rigid fit."""

import json
import pathlib

import cv2
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cslx.calibration import (
    board_points,
    calibrate_camera,
    calibrate_planes,
    detect_corners,
    edge_crossings,
    fit_plane,
    fit_rigid,
    rodrigues,
    rotation_to_rvec,
)
from cslx.sensor import CalibrationError, cross_projector_planes, plane_angle_deg
from cslx.sensor.camera import Camera, pixel_to_ray, project

DATA = pathlib.Path(__file__).resolve().parents[1] / "data" / "opencv-samples"
CALIB1 = pathlib.Path(__file__).resolve().parents[3] / "shared" / "data" / "opencv-extra-calib1"


@pytest.fixture(scope="module")
def samples():
    ref = json.loads((DATA / "reference.json").read_text())
    corners, skipped = detect_corners([DATA / n for n in ref["images"]], (9, 6))
    pts = [c for c in corners if c is not None]
    obj = board_points((9, 6), 1.0)
    return ref, pts, skipped, obj, calibrate_camera(pts, obj, (640, 480))


def test_opencv_samples_match_reference(samples):
    ref, pts, skipped, _, cal = samples
    r = ref["k1k2p1p2 (flags=CALIB_FIX_K3)"]
    assert skipped == [] and len(pts) == 13
    assert cal.converged
    # The tolerances: 1e-3 px RMS and 0.1 % in focal length.
    assert abs(cal.rms - r["rms"]) < 1e-3
    K = np.asarray(cal.camera.K)
    assert abs(K[0, 0] / r["K"][0][0] - 1) < 1e-3
    assert abs(K[1, 1] / r["K"][1][1] - 1) < 1e-3


def test_opencv_samples_match_live_calibrate_camera(samples):
    _, pts, _, obj, cal = samples
    rms, K, dist, _, tvecs, sd_int, _, per_view = cv2.calibrateCameraExtended(
        [obj.astype(np.float32)] * len(pts),
        [p.astype(np.float32) for p in pts],
        (640, 480),
        None,
        None,
        flags=cv2.CALIB_FIX_K3,
    )
    # Same objective, same model: the minimisers agree to the solvers' tolerances (OpenCV
    # stops after 30 LM steps, in float32 corners: 1e-5 relative is ample and still tight).
    assert cal.rms == pytest.approx(rms, abs=1e-6)
    np.testing.assert_allclose(np.asarray(cal.camera.K), K, rtol=2e-5, atol=1e-9)
    np.testing.assert_allclose(np.asarray(cal.camera.dist), dist.ravel()[:4], rtol=1e-3, atol=2e-6)
    np.testing.assert_allclose(cal.per_image_rms, per_view.ravel(), rtol=1e-4)
    np.testing.assert_allclose(cal.tvecs, np.asarray(tvecs)[..., 0], rtol=1e-4, atol=1e-5)
    # OpenCV's stdDeviationsIntrinsics use the same σ² = SSR / (2N − p) (J of the solution).
    ours = [cal.std[k] for k in ("fx", "fy", "u0", "v0", "k1", "k2", "p1", "p2")]
    np.testing.assert_allclose(ours, sd_int.ravel()[:8], rtol=1e-2)


def test_closed_form_init_is_close_to_refined(samples):
    *_, cal = samples
    init, fin = cal.init, cal.camera
    # Zhang's closed form ignores distortion (k1 ≈ −0.29 here), so a few % is expected.
    assert abs(float(init.fx) / float(fin.fx) - 1) < 0.02
    assert abs(float(init.fy) / float(fin.fy) - 1) < 0.02
    assert abs(float(init.u0 - fin.u0)) < 15 and abs(float(init.v0 - fin.v0)) < 15


def test_detect_corners_skips_images_without_board():
    blank = np.full((120, 160), 128, np.uint8)
    img = cv2.imread(str(DATA / "left01.jpg"), cv2.IMREAD_GRAYSCALE)
    corners, skipped = detect_corners([blank, img], (9, 6), names=["blank", "left01"])
    assert corners[0] is None and skipped == ["blank"]
    assert corners[1].shape == (54, 2)


@pytest.mark.skipif(not CALIB1.exists(), reason=f"{CALIB1} absent (shared data, not copied)")
def test_calib1_matches_bouguet_toolbox():
    pts = np.loadtxt(CALIB1 / "image_points.txt").reshape(7, 35, 2)
    cal = calibrate_camera(list(pts), board_points((7, 5), 2.54), (640, 480))
    # README: fc, cc, kc of the Bouguet Caltech toolbox and their standard deviations.
    fc, cc = (809.94790, 806.55964), (361.99611, 214.39514)
    kc = (-0.12821, -0.39441, -0.00435, -0.00732)
    sd = dict(fx=9.4836, fy=8.8277, u0=8.5363, v0=13.2763, k1=0.03972, k2=0.52176)
    got = dict(fx=cal.camera.fx, fy=cal.camera.fy, u0=cal.camera.u0, v0=cal.camera.v0)
    want = dict(fx=fc[0], fy=fc[1], u0=cc[0], v0=cc[1])
    for k in want:
        # Same minimiser: far inside the stated uncertainty (1 % of it).
        assert abs(float(got[k]) - want[k]) < 0.01 * sd[k], k
    np.testing.assert_allclose(np.asarray(cal.camera.dist), kc, atol=5e-5)
    assert cal.tvecs[0] == pytest.approx([-3.26609, 2.16111, 76.72193], abs=1e-3)


def test_rotation_vectors_match_opencv():
    rng = np.random.default_rng(1)
    rv = np.concatenate([rng.normal(size=(20, 3)), [[0, 0, 0], [np.pi - 1e-9, 0, 0]]])
    for r in rv:
        R_cv, _ = cv2.Rodrigues(r)
        R = np.asarray(rodrigues(jnp.asarray(r)))
        np.testing.assert_allclose(R, R_cv, atol=1e-12)
        back = np.asarray(rotation_to_rvec(jnp.asarray(R_cv)))
        np.testing.assert_allclose(cv2.Rodrigues(back)[0], R_cv, atol=1e-9)
    g = jax.grad(lambda r: jnp.sum(rodrigues(r)))(jnp.zeros(3))
    assert np.all(np.isfinite(np.asarray(g)))


# ----------------------------------------------------------------------------- synthetic rig


def _random_poses(rng, n, pattern, square, depth=(380.0, 520.0)):
    """Board poses facing the camera, tilted by up to ~35°, board centre near the axis."""
    cols, rows = pattern
    centre = np.array([(cols - 1) * square / 2, (rows - 1) * square / 2, 0])
    Rs, ts = [], []
    for _ in range(n):
        angles = rng.uniform(-35, 35, 2)
        R = Rotation.from_euler("xyz", [angles[0], angles[1], rng.uniform(-10, 10)], True)
        R = R.as_matrix()
        c = np.array([rng.uniform(-20, 20), rng.uniform(-20, 20), rng.uniform(*depth)])
        Rs.append(R)
        ts.append(c - R @ centre)
    return np.array(Rs), np.array(ts)


def _camera():
    K = ((700.0, 0, 322.0), (0, 698.0, 241.0), (0, 0, 1))
    return Camera.from_matrix(jnp.asarray(K), jnp.asarray((-0.2, 0.1, 5e-4, -3e-4)), (640, 480))


def test_synthetic_round_trip_recovers_intrinsics():
    rng = np.random.default_rng(0)
    pattern, square = (10, 7), 25.0
    cam = _camera()
    obj = board_points(pattern, square)
    Rs, ts = _random_poses(rng, 9, pattern, square)
    pts = [
        np.asarray(project(jnp.asarray(obj @ R.T + t), cam)) for R, t in zip(Rs, ts, strict=True)
    ]
    noisy = [p + rng.normal(0, 0.1, p.shape) for p in pts]
    cal = calibrate_camera(noisy, obj, (640, 480))
    got = np.concatenate([[cal.camera.fx, cal.camera.fy, cal.camera.u0, cal.camera.v0],
                          np.asarray(cal.camera.dist)])  # fmt: skip
    want = np.concatenate([[cam.fx, cam.fy, cam.u0, cam.v0], np.asarray(cam.dist)])
    sd = np.array([cal.std[k] for k in ("fx", "fy", "u0", "v0", "k1", "k2", "p1", "p2")])
    # Unbiased maximum-likelihood estimates: within 4 of their own standard deviations.
    assert np.all(np.abs(got - want) < 4 * sd), (got - want) / sd
    # RMS of 2-D Gaussian noise with σ = 0.1 px: σ √2 √((2N − p) / 2N).
    n, p = 70 * 9, 8 + 6 * 9
    assert cal.rms == pytest.approx(0.1 * np.sqrt(2 * (2 * n - p) / (2 * n)), rel=0.1)
    poses = zip(Rs, ts, cal.rvecs, cal.tvecs, cal.std["rvecs"], cal.std["tvecs"], strict=True)
    for R, t, rv, tv, srv, stv in poses:
        assert np.all(np.abs(rotation_to_rvec(jnp.asarray(R)) - rv) < 4 * srv + 1e-9)
        assert np.all(np.abs(tv - t) < 4 * stv)


def _draw_laser(cam, R, t, planes, width_mm=0.6, level=200.0):
    """Laser-on RGB frame: grey board, red Gaussian sheets where the planes meet the board.

    An independent reference renderer: every pixel's ray is cut with the board plane and
    the distance of that point to each laser plane sets the red level.
    """
    w, h = cam.image_size
    uu, vv = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    uv = np.stack([uu.ravel(), vv.ravel()], 1)
    ray = np.asarray(pixel_to_ray(jnp.asarray(uv), cam, normalize=False))
    n = R[:, 2]
    X = ray * ((n @ t) / (ray @ n))[:, None]
    img = np.full((h * w, 3), 110.0)
    for pl in planes:
        d = (X @ pl + 1) / np.linalg.norm(pl)
        img[:, 0] += level * np.exp(-0.5 * (d / width_mm) ** 2)
    return np.clip(img, 0, 255).reshape(h, w, 3).astype(np.uint8)


@pytest.fixture(scope="module")
def laser_rig():
    rng = np.random.default_rng(3)
    pattern, square = (10, 7), 25.0
    cam = _camera()
    # A cross projector beside the camera, aimed at the middle of the working range.
    planes = cross_projector_planes(origin=(-60.0, -60.0, 0.0), target=(0.0, 0.0, 450.0))
    obj = board_points(pattern, square)
    Rs, ts = _random_poses(rng, 6, pattern, square)
    pts = [
        np.asarray(project(jnp.asarray(obj @ R.T + t), cam)) for R, t in zip(Rs, ts, strict=True)
    ]
    pts = [p + rng.normal(0, 0.05, p.shape) for p in pts]
    cal = calibrate_camera(pts, obj, (640, 480))
    images = [_draw_laser(cam, R, t, planes) for R, t in zip(Rs, ts, strict=True)]
    return dict(cam=cam, planes=planes, Rs=Rs, ts=ts, cal=cal, images=images, pattern=pattern)


def test_laser_planes_recovered(laser_rig):
    r = laser_rig
    pc = calibrate_planes(r["cal"], r["images"], r["pattern"], 25.0, method="simple")
    for k in range(2):
        # Normal direction error: the planes are known exactly; the corners carry 0.05 px
        # noise and the stripe centres are parabola peaks (≈ 0.05 px): ≤ 0.1° is comfortable.
        assert plane_angle_deg(pc.planes[k], r["planes"][k]) < 0.1
        assert abs(1 / np.linalg.norm(pc.planes[k]) - 1 / np.linalg.norm(r["planes"][k])) < 0.5
        assert pc.fits[k].rms < 0.1
        assert np.all(np.isfinite(pc.fits[k].std))
    assert pc.angle_deg == pytest.approx(90.0, abs=0.2)
    assert (pc.counts > 50).all()


def test_edge_crossings_lie_on_square_edges(laser_rig):
    r = laser_rig
    pc = calibrate_planes(r["cal"], r["images"], r["pattern"], 25.0, method="simple")
    cal = r["cal"]
    sel = pc.views[0] == 0
    feats = edge_crossings(pc.pixels[0][sel], cal.camera, cal.rotations[0], cal.tvecs[0], 25.0, "h")
    assert len(feats) >= 5
    from cslx.calibration import lift_to_board

    _, Xt = lift_to_board(feats, cal.camera, cal.rotations[0], cal.tvecs[0])
    np.testing.assert_allclose(Xt[:, 0] / 25.0, np.round(Xt[:, 0] / 25.0), atol=1e-3)


def test_laser_degenerate_inputs_raise(laser_rig):
    r = laser_rig
    blank = [np.full_like(im, 110) for im in r["images"]]
    with pytest.raises(CalibrationError, match="horizontal line: on the board in 0 of 6"):
        calibrate_planes(r["cal"], blank, r["pattern"], 25.0, method="simple")
    with pytest.raises(CalibrationError, match="laser images for"):
        calibrate_planes(r["cal"], r["images"][:2], r["pattern"], 25.0, method="simple")
    # Same image for every pose: the boards are parallel (the same pose) for the fit.
    same = [r["images"][0]] * len(r["images"])
    cal = r["cal"]
    import dataclasses

    one_pose = dataclasses.replace(
        cal, rvecs=np.repeat(cal.rvecs[:1], len(cal.rvecs), 0), tvecs=np.repeat(cal.tvecs[:1], 6, 0)
    )
    with pytest.raises(CalibrationError, match="nearly parallel"):
        calibrate_planes(one_pose, same, r["pattern"], 25.0, method="simple")


def test_fit_plane_rejects_outliers_and_degenerate_sets():
    rng = np.random.default_rng(0)
    plane = np.array([0.001, -0.002, -1 / 300])
    xy = rng.uniform(-80, 80, (400, 2))
    z = -(xy @ plane[:2] + 1) / plane[2]
    P = np.column_stack([xy, z]) + rng.normal(0, 0.02, (400, 3))
    P[:40] += rng.normal(0, 5, (40, 3))  # 10 % gross outliers
    fit = fit_plane(P)
    assert plane_angle_deg(fit.plane, plane) < 0.05
    assert fit.inliers[40:].mean() > 0.97 and fit.inliers[:40].mean() < 0.3
    assert fit.rms == pytest.approx(0.02, rel=0.25)
    with pytest.raises(CalibrationError, match="too few"):
        fit_plane(P[:5])
    line = np.outer(np.linspace(0, 1, 50), [1.0, 2.0, 3.0]) + [0, 0, 200]
    with pytest.raises(CalibrationError, match="collinear"):
        fit_plane(line)


def test_fit_rigid_with_noise_and_reflection():
    rng = np.random.default_rng(0)
    R = Rotation.random(random_state=1).as_matrix()
    T = np.array([150.0, -20.0, 230.0])
    P = rng.uniform(-100, 100, (30, 3))
    Q = P @ R.T + T + rng.normal(0, 0.05, (30, 3))
    R_est, T_est, res = fit_rigid(P, Q)
    # Reference: SciPy's Wahba solution of the centred sets.
    R_ref = Rotation.align_vectors(Q - Q.mean(0), P - P.mean(0))[0].as_matrix()
    np.testing.assert_allclose(R_est, R_ref, atol=1e-9)
    assert np.linalg.det(R_est) == pytest.approx(1.0)
    assert np.linalg.norm(T_est - T) < 0.1
    assert np.sqrt(np.mean(res**2)) == pytest.approx(0.05 * np.sqrt(3), rel=0.3)
    # A mirrored target: the best orthogonal map is a reflection; the fit must stay proper.
    M = np.diag([1.0, 1.0, -1.0])
    R_m, _, res_m = fit_rigid(P, P @ M.T)
    assert np.linalg.det(R_m) == pytest.approx(1.0)
    np.testing.assert_allclose(R_m.T @ R_m, np.eye(3), atol=1e-12)
    R_ref_m = Rotation.align_vectors(P @ M.T - (P @ M.T).mean(0), P - P.mean(0))[0].as_matrix()
    np.testing.assert_allclose(R_m, R_ref_m, atol=1e-9)
    assert res_m.max() > 1.0
    with pytest.raises(CalibrationError, match="collinear"):
        fit_rigid(np.outer(np.arange(5.0), [1, 1, 1]), np.outer(np.arange(5.0), [1, 0, 0]))


# ----------------------------------------------------------------------------- command line


def test_cli_camera_only_and_missing_laser_images(tmp_path, capsys):
    from cslx.cli import main

    out = tmp_path / "cam.json"
    args = ["calibrate", "--images", str(DATA), "--pattern", "9x6", "--square", "1"]
    assert main([*args, "--out", str(out)]) == 2
    assert "--laser-images is required" in capsys.readouterr().err
    assert main([*args, "--camera-only", "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    ref = json.loads((DATA / "reference.json").read_text())["k1k2p1p2 (flags=CALIB_FIX_K3)"]
    assert data["camera_only"] is True and "planes" not in data
    assert data["rms_px"] == pytest.approx(ref["rms"], abs=1e-3)
    assert len(data["per_image_rms_px"]) == 13
    with pytest.raises(CalibrationError, match="planes"):
        from cslx.sensor import load_sensor

        load_sensor(out)
    assert main([*args, "--pattern", "9by6", "--camera-only", "--out", str(out)]) == 2


@pytest.mark.slow
def test_cli_on_rendered_boards(tmp_path):
    """Render plain + laser boards with the true sensor, run `cslx calibrate`, compare."""
    from cslx.cli import main
    from cslx.sensor import default_sensor, load_sensor
    from cslx.sim import render_calibration

    true = default_sensor()
    d = render_calibration(true, n_poses=6, seed=4, supersample=1)
    for sub, key in (("plain", "plain"), ("laser", "laser")):
        (tmp_path / sub).mkdir()
        for i, im in enumerate(d[key]):
            cv2.imwrite(str(tmp_path / sub / f"{i:02d}.png"), im[..., ::-1])
    rob = tmp_path / "robot.csv"
    R = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    P = np.random.default_rng(0).uniform(-100, 100, (6, 3)) + [0, 0, 300]
    np.savetxt(rob, np.hstack([P, P @ R.T + [150, 0, 230]]), delimiter=",",
               header="x_c,y_c,z_c,x_r,y_r,z_r", comments="")  # fmt: skip
    out = tmp_path / "sensor.json"
    rc = main(["calibrate", "--images", str(tmp_path / "plain"), "--laser-images",
               str(tmp_path / "laser"), "--robot-points", str(rob), "--out", str(out)])  # fmt: skip
    assert rc == 0
    s = load_sensor(out)
    assert float(s.camera.fx) == pytest.approx(float(true.camera.fx), rel=5e-3)
    assert float(s.camera.fy) == pytest.approx(float(true.camera.fy), rel=5e-3)
    for k in range(2):
        assert plane_angle_deg(s.planes[k], true.planes[k]) < 0.3
    np.testing.assert_allclose(np.asarray(s.R_cr), R, atol=1e-9)
