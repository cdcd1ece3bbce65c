"""`calibrate_sensor`: one line laser or a cross, the laser on the board, gates, the CLI.

The boards are drawn here by an independent reference (every pixel's ray cut with the board,
a checker pattern and Gaussian laser sheets, 2×2 supersampled), with the laser on in the
very images the corners come from: the case of a user with one photo per pose.
"""

import json

import cv2
import jax.numpy as jnp
import numpy as np
import pytest

from cslx.calibration import PlaneGates, board_points, calibrate_sensor
from cslx.sensor import CalibrationError, default_sensor, load_sensor, plane_angle_deg
from cslx.sensor.camera import pixel_to_ray

PATTERN, SQUARE = (10, 7), 25.0
TRUE = default_sensor()


def _rot(ax, ay, az):
    return cv2.Rodrigues(np.array([ax, ay, 0.0]))[0] @ cv2.Rodrigues(np.array([0.0, 0.0, az]))[0]


def _poses(rng, n, planes):
    """Random board poses, whole board in view, every plane in `planes` splitting the board."""
    cols, rows = PATTERN
    K = np.asarray(TRUE.camera.K)
    centre = np.array([(cols - 1) / 2, (rows - 1) / 2, 0.0]) * SQUARE
    gx, gy = np.meshgrid(np.linspace(-1, cols, 12), np.linspace(-1, rows, 9))
    area = np.stack([gx.ravel(), gy.ravel(), 0 * gx.ravel()], 1) * SQUARE
    out = []
    while len(out) < n:
        R = _rot(*np.deg2rad(rng.uniform(-22, 22, 2)), np.deg2rad(rng.uniform(-8, 8)))
        z = rng.uniform(400, 520)
        u, v = rng.uniform(340, 420), rng.uniform(240, 290)
        t = np.array([(u - K[0, 2]) * z / K[0, 0], (v - K[1, 2]) * z / K[1, 1], z]) - R @ centre
        X = area @ R.T + t
        uv = cv2.projectPoints(X, np.zeros(3), np.zeros(3), K, np.asarray(TRUE.camera.dist))[0]
        uv = uv[:, 0]
        if uv.min() < 10 or uv[:, 0].max() > 629 or uv[:, 1].max() > 469:
            continue
        side = (X @ np.asarray(planes).T + 1) > 0
        if np.any(np.minimum(side.mean(0), 1 - side.mean(0)) < 0.1):
            continue
        out.append((R, t))
    return out


@pytest.fixture(scope="module")
def rays():
    w, h = TRUE.camera.image_size
    ss = 2
    uu, vv = np.meshgrid((np.arange(w * ss) + 0.5) / ss - 0.5, (np.arange(h * ss) + 0.5) / ss - 0.5)
    uv = np.stack([uu.ravel(), vv.ravel()], 1)
    ray = pixel_to_ray(jnp.asarray(uv), TRUE.camera, normalize=False)
    return np.asarray(ray, np.float32), ss


def _draw(rays, R, t, planes, rng, sheet_mm=0.8):
    """(H, W, 3) uint8: the board (with the laser sheets of `planes` on it) on a dark wall."""
    ray, ss = rays
    w, h = TRUE.camera.image_size
    R, t = R.astype(np.float32), t.astype(np.float32)
    n = R[:, 2]
    X = ray * ((n @ t) / (ray @ n))[:, None]
    xb = (X - t) @ R
    x, y = xb[:, 0] / SQUARE, xb[:, 1] / SQUARE
    cols, rows = PATTERN
    squares = (x > -1) & (x < cols) & (y > -1) & (y < rows)
    board = (x > -1.5) & (x < cols + 0.5) & (y > -1.5) & (y < rows + 0.5)
    black = (np.floor(x) + np.floor(y)) % 2 == 0
    refl = np.where(board, np.where(squares & black, 0.06, 0.8), 0.12)
    laser = np.zeros(len(X))
    for p in planes:
        d = (X @ p.astype(np.float32) + 1) / np.linalg.norm(p)
        laser += np.exp(-2 * (d / sheet_mm) ** 2)
    lit = laser * (refl / 0.8) * board
    img = 170 * refl[:, None] + lit[:, None] * np.array([220, 15, 9], np.float32)
    img = img.reshape(h, ss, w, ss, 3).mean(axis=(1, 3)) + rng.normal(0, 1.0, (h, w, 3))
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def _captures(rays, stripes, n=5, seed=0):
    rng = np.random.default_rng(seed)
    planes = [np.asarray(TRUE.planes[TRUE.plane_index(s)]) for s in stripes]
    return [_draw(rays, R, t, planes, rng) for R, t in _poses(rng, n, planes)]


@pytest.fixture(scope="module")
def line_v(rays):
    return _captures(rays, ("v",), seed=1)


@pytest.fixture(scope="module")
def cross(rays):
    return _captures(rays, ("h", "v"), seed=2)


def _plane_err(result, stripe):
    k = result.planes.stripes.index(stripe)
    true = np.asarray(TRUE.planes[TRUE.plane_index(stripe)])
    est = result.planes.planes[k]
    return plane_angle_deg(est, true), abs(1 / np.linalg.norm(est) - 1 / np.linalg.norm(true))


def test_line_laser_on_the_board_gives_one_plane(line_v):
    r = calibrate_sensor(line_v, PATTERN, SQUARE, laser_images=line_v)
    assert r.skipped == [] and len(r.used) == len(line_v)
    assert r.planes.stripes == ("v",) and r.planes.planes.shape == (1, 3)
    assert "h" in r.planes.rejected  # the absent horizontal line is refused, with a reason
    angle, dist = _plane_err(r, "v")
    assert angle < 0.3 and dist < 0.5
    fit = r.planes.fits[0]
    assert fit.rms < 0.2 and fit.inliers.mean() > 0.7
    assert np.all(np.isfinite(fit.covariance)) and np.all(fit.std > 0)
    s = r.sensor
    assert s.n_planes == 1 and s.plane_stripes == ("v",)
    # The vertical stripe triangulates onto the true plane; the horizontal one is refused.
    uv = r.planes.pixels[0][:50]
    X = np.asarray(s.triangulate(jnp.asarray(uv), "v"))
    n = np.asarray(TRUE.planes[1])
    assert np.abs((X @ n + 1) / np.linalg.norm(n)).max() < 1.0
    with pytest.raises(CalibrationError, match="no laser plane for the horizontal stripe"):
        s.triangulate(jnp.asarray(uv), 0)
    with pytest.raises(CalibrationError, match="tracking needs 2 laser planes"):
        s.require_planes(2, "tracking")


def test_cross_on_the_board_gives_two_planes_and_lines_forced(cross, line_v):
    r = calibrate_sensor(cross, PATTERN, SQUARE, laser_images=cross)
    assert r.planes.stripes == ("h", "v") and r.planes.rejected == {}
    for s in "hv":
        angle, dist = _plane_err(r, s)
        assert angle < 0.3 and dist < 0.5
    assert r.planes.angle_deg == pytest.approx(90.0, abs=0.5)
    one = calibrate_sensor(cross, PATTERN, SQUARE, laser_images=cross, lines=1)
    assert len(one.planes.stripes) == 1 and "--lines 1" in next(iter(one.planes.rejected.values()))
    with pytest.raises(CalibrationError, match="need 2 laser line.*horizontal line"):
        calibrate_sensor(line_v, PATTERN, SQUARE, laser_images=line_v, lines=2)


def test_poor_plane_refused_with_numbers(line_v):
    gates = PlaneGates(max_rms_mm=1e-4)
    with pytest.raises(CalibrationError, match=r"vertical line: poor plane fit \(RMS"):
        calibrate_sensor(line_v, PATTERN, SQUARE, laser_images=line_v, gates=gates)
    with pytest.raises(CalibrationError, match="found in 2 of 6 images; at least 3"):
        blank = [np.full_like(line_v[0], 40)] * 4 + line_v[:2]
        calibrate_sensor(blank, PATTERN, SQUARE, laser_images=blank)


def test_robot_board_frame(cross):
    """The robot frame from a board whose corners are known in the robot frame (Fig. 20)."""
    r0 = calibrate_sensor(cross, PATTERN, SQUARE)
    assert r0.sensor is None and r0.planes is None
    R0, t0 = r0.camera.rotations[0], r0.camera.tvecs[0]
    P_c = board_points(PATTERN, SQUARE) @ R0.T + t0
    R_cr, T_cr = np.asarray(TRUE.R_cr), np.asarray(TRUE.T_cr)
    r = calibrate_sensor(
        cross, PATTERN, SQUARE, laser_images=cross, robot_board=(0, P_c @ R_cr.T + T_cr)
    )
    np.testing.assert_allclose(r.R_cr, R_cr, atol=1e-9)
    np.testing.assert_allclose(r.T_cr, T_cr, atol=1e-6)
    np.testing.assert_allclose(np.asarray(r.sensor.R_cr), R_cr, atol=1e-6)


# ----------------------------------------------------------------------------- command line


def _write(folder, images):
    folder.mkdir()
    for i, im in enumerate(images):
        cv2.imwrite(str(folder / f"{i:02d}.png"), im[..., ::-1])
    return folder


def test_cli_line_laser_same_images_skips_bad_ones(tmp_path, line_v, capsys):
    from cslx.cli import main

    imgs = _write(tmp_path / "imgs", line_v)
    (imgs / "90_broken.png").write_text("not an image")
    cv2.imwrite(str(imgs / "91_blank.png"), np.full((480, 640, 3), 60, np.uint8))
    out = tmp_path / "line.json"
    rc = main(["calibrate", "--images", str(imgs), "--laser-images", str(imgs), "--out", str(out)])
    err = capsys.readouterr()
    assert rc == 0, err.err
    assert "90_broken.png: unreadable" in err.err and "91_blank.png: no 10x7 board" in err.err
    assert "2 of 7 images skipped (5 used)" in err.err
    assert "one laser line" in err.out
    data = json.loads(out.read_text())
    assert len(data["planes"]) == 1 and data["stripes"] == ["v"]
    assert "plane_angle_deg" not in data
    for key in ("plane_rms_mm", "plane_points", "plane_inlier_share", "plane_covariance"):
        assert len(data[key]) == 1
    assert np.asarray(data["plane_covariance"]).shape == (1, 3, 3)
    assert set(data["skipped_images"]) == {"90_broken.png", "91_blank.png"}
    assert "h" in data["rejected_lines"] and data["lines_detected"] == ["v"]
    s = load_sensor(out)
    assert s.plane_stripes == ("v",)

    # extract --calib with the one-plane file: the vertical stripe only, triangulated.
    csv = tmp_path / "c.csv"
    rc = main(["extract", str(imgs / "00.png"), "--calib", str(out), "--out", str(csv)])
    err = capsys.readouterr().err
    assert rc == 0, err and "holds one laser plane (v stripe)" in err
    rows = [r.split(",") for r in csv.read_text().splitlines()]
    assert rows[0][:7] == ["image", "stripe", "u", "v", "x", "y", "z"]
    assert len(rows) > 100 and {r[1] for r in rows[1:]} == {"v"}
    rc = main(["extract", str(imgs / "00.png"), "--calib", str(out), "--stripe", "h",
               "--out", str(csv)])  # fmt: skip
    assert rc == 2 and "no laser plane for the horizontal stripe" in capsys.readouterr().err

    # The tracker needs the cross and says so.
    from cslx.runtime.tracker import Tracker

    with pytest.raises(CalibrationError, match="tracking needs 2 laser planes.*holds 1"):
        Tracker.from_calibration(out)


def test_cli_bad_inputs_clear_words(tmp_path, line_v, capsys):
    from cslx.cli import main

    imgs = _write(tmp_path / "imgs", line_v[:4])
    cam = tmp_path / "cam.json"
    base = ["calibrate", "--images", str(imgs)]
    assert main([*base, "--camera-only", "--out", str(tmp_path)]) == 2
    assert "is a directory" in capsys.readouterr().err
    assert main([*base, "--camera-only", "--out", str(tmp_path / "no" / "c.json")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main([*base, "--laser-images", str(imgs), "--robot-points", str(imgs),
                 "--out", str(cam)]) == 2  # fmt: skip
    assert "is a directory" in capsys.readouterr().err
    # A cross required of a line laser: refused, nothing written.
    assert main([*base, "--laser-images", str(imgs), "--lines", "2", "--out", str(cam)]) == 2
    assert "need 2 laser line(s): horizontal line" in capsys.readouterr().err
    assert not cam.exists()
    assert main([*base, "--camera-only", "--out", str(cam)]) == 0
    capsys.readouterr()
    # A camera-only calibration where a sensor is needed: clear words, not "missing key".
    with pytest.raises(CalibrationError, match="camera-only calibration"):
        load_sensor(cam)
    rc = main(["extract", str(imgs / "00.png"), "--calib", str(cam), "--out",
               str(tmp_path / "c.csv")])  # fmt: skip
    err = capsys.readouterr().err
    assert rc == 2 and "camera-only calibration" in err and "missing key" not in err
    with pytest.raises(CalibrationError, match="is a directory"):
        load_sensor(tmp_path)
    # The previous file survives a failed run (no board anywhere: nothing is written).
    before = cam.read_bytes()
    blank = _write(tmp_path / "blank", [np.full_like(line_v[0], 50)] * 3)
    assert main(["calibrate", "--images", str(blank), "--camera-only", "--out", str(cam)]) == 2
    assert "found in 0 of 3 images" in capsys.readouterr().err
    assert cam.read_bytes() == before


@pytest.mark.slow
def test_cli_on_rendered_single_line_boards(tmp_path):
    """The JAX renderer's single line laser on the board, one image per pose, via the CLI."""
    from cslx.cli import main
    from cslx.sim import render_calibration

    d = render_calibration(TRUE, n_poses=6, seed=7, supersample=1, lines=("h",))
    imgs = _write(tmp_path / "imgs", list(d["laser"]))
    out = tmp_path / "s.json"
    assert main(["calibrate", "--images", str(imgs), "--laser-images", str(imgs),
                 "--out", str(out)]) == 0  # fmt: skip
    s = load_sensor(out)
    assert s.plane_stripes == ("h",)
    assert plane_angle_deg(s.planes[0], TRUE.planes[0]) < 0.3
