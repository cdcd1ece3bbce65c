"""Tracker on rendered frames vs `true_weld_line`; bad frames; the Kalman model; closed loop."""

import math
import pathlib

import numpy as np
import pytest

from cslx.runtime.line_filter import KalmanConfig, WeldLineFilter
from cslx.runtime.tracker import Tracker
from cslx.sensor import default_sensor

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def tracker():
    lines = []
    tr = Tracker.from_calibration(default_sensor(), log=lines.append)
    tr.lines = lines
    return tr


@pytest.fixture(scope="module")
def frames(render_scenes):
    kinds = ("straight", "cross", "cross")
    scenes = render_scenes(default_sensor(), kinds, 41)
    return [(kind, img, gt) for kind, (img, gt) in zip(kinds, scenes, strict=True)]


def test_compile_logged(tracker):
    assert tracker.compile_s > 0
    assert any("compiled" in line for line in tracker.lines)


def test_stripe_x_is_the_triangulated_principal_point(tracker):
    """x_ref (NumPy, no start-up compiles) equals `triangulate` of (u0, v0) on the wall."""
    from cslx.sensor import triangulate

    cam = tracker.sensor.camera
    uv = np.array([[float(cam.u0), float(cam.v0)]])
    X = np.asarray(triangulate(default_sensor(), uv, 0, robot_frame=True))[0]
    assert abs(X[2]) < 1e-3  # the point lies on the wall (z_r = 0)
    assert tracker.x_ref == pytest.approx(float(X[0]), abs=1e-3)


def test_offset_and_junction_on_rendered_frames(tracker, frames):
    need = tracker.kalman.junction_confirm_min
    assert need >= 2
    for kind, img, gt in frames:
        tracker.reset()
        # a still robot sees the same frame again (odometry 0): the junction is confirmed
        # on the `junction_confirm_min`-th agreeing sighting, not before
        obs = [tracker.step(img)] + [tracker.step(img, odometry=0.0) for _ in range(need - 1)]
        for o in obs:
            assert o.status == "ok"
            assert abs(o.offset_mm - gt["offset_mm"]) < 1.0, (kind, o.offset_mm, gt["offset_mm"])
            assert abs(o.bead_width_mm - gt["bead_width_mm"]) < 3.0
            assert 0.0 < o.confidence <= 1.0
        assert not any(o.junction for o in obs[:-1])  # fewer sightings are not enough
        last = obs[-1]
        if kind == "cross":
            assert last.junction
            assert abs(last.junction_x_mm - gt["junction_x_mm"]) < 3.0
        else:
            assert not last.junction and math.isnan(last.junction_x_mm)


def test_bad_frames_give_zero_confidence(tracker, frames):
    tracker.reset()
    good = frames[0][1]
    tracker.step(good)
    rng = np.random.default_rng(0)
    bad = {
        "no frame": None,
        "wrong frame shape": good[:240],
        "wrong frame dtype": good.astype(np.float32),
        "black frame": np.zeros_like(good),
        "saturated frame": np.full_like(good, 255),
        "no stripe found": rng.integers(0, 40, good.shape, dtype=np.uint8),
        "not an image": "frame.png",
    }
    for why, frame in bad.items():
        n_lines = len(tracker.lines)
        obs = tracker.step(frame)
        assert obs.status.startswith(why), (why, obs.status)
        assert obs.confidence == 0.0 and math.isnan(obs.offset_mm)
        assert len(tracker.lines) == n_lines + 1 and why in tracker.lines[-1]
    assert tracker.step(good).status == "ok"  # and it recovers


def test_kalman_recovers_heading_from_odometry():
    """Bead centres along a line at 3° seen while driving 1.5 mm/frame: heading → 3°."""
    rng = np.random.default_rng(1)
    x_ref, theta, e0 = 150.0, math.radians(3.0), 2.0
    kf = WeldLineFilter(KalmanConfig(), x_ref)
    travelled = 0.0
    for k in range(80):
        if k:
            kf.predict(1.5, 0.0)
            travelled += 1.5
        true_e = e0 + math.tan(theta) * travelled
        kf.update(x_ref + rng.normal(0, 0.3), true_e + rng.normal(0, 0.2), 0.5)
    assert math.degrees(kf.x[1]) == pytest.approx(3.0, abs=0.5)
    assert kf.x[0] == pytest.approx(e0 + math.tan(theta) * travelled, abs=0.3)
    # a rotation of the robot by δ moves the line by −x_ref δ and turns it by −δ
    before = kf.x.copy()
    kf.predict(0.0, math.radians(1.0))
    assert kf.x[0] == pytest.approx(before[0] - x_ref * math.radians(1.0))
    assert kf.x[1] == pytest.approx(before[1] - math.radians(1.0))


def test_closed_loop_short(tracker):
    from cslx.sim.closed_loop import run_closed_loop

    res = run_closed_loop(
        n_frames=30, seed=3, tracker=tracker, start_offset_mm=3.0, start_heading_deg=0.0
    )
    assert res["n_counted"] >= 25
    # starts 3 mm off: the controller reduces it while the tracker stays within ~1 mm
    assert res["mean_error_mm"] < 3.0 and res["max_error_mm"] < 4.0
    assert res["mean_abs_estimation_error_mm"] < 1.0
    errs = [r["tracking_error_mm"] for r in res["rows"]]
    assert np.mean(errs[-5:]) < np.mean(errs[:5])


def test_gate_reacquires_after_consistent_rejections():
    """A wrong prediction locks the truth out; three agreeing centres restart the filter."""
    rng = np.random.default_rng(4)
    c = KalmanConfig()
    kf = WeldLineFilter(c, 150.0)
    for _ in range(30):  # settled on a weld at y = 0
        kf.predict(1.5, 0.0)
        kf.update(150.0, rng.normal(0, 0.1), 0.8)
    assert abs(kf.x[0]) < 0.3
    accepted = []
    for _ in range(6):  # the weld now seen 6 mm away (a new weld, or a lateral jump)
        kf.predict(1.5, 0.0)
        accepted.append(kf.update(150.0, 6.0 + rng.normal(0, 0.1), 0.8))
    assert accepted[: c.reset_after - 1] == [False] * (c.reset_after - 1)
    assert accepted[c.reset_after - 1] and kf.restarts == 1
    assert abs(kf.x[0] - 6.0) < 0.5


def test_gate_does_not_restart_on_disagreeing_clutter():
    rng = np.random.default_rng(5)
    c = KalmanConfig()
    kf = WeldLineFilter(c, 150.0)
    for _ in range(30):
        kf.predict(1.5, 0.0)
        kf.update(150.0, rng.normal(0, 0.1), 0.8)
    for k in range(c.give_up_after - 1):  # outliers that do not agree with each other
        kf.predict(1.5, 0.0)
        assert not kf.update(150.0, (8.0 + 3 * k) * (-1) ** k, 0.8)
    assert kf.restarts == 0 and abs(kf.x[0]) < 0.5
    kf.predict(1.5, 0.0)
    assert kf.update(150.0, 30.0, 0.8) and kf.restarts == 1  # gives up: restarts anyway


def _drift(config: KalmanConfig, rate: float = 1.2, seed: int = 9, odometry: bool = False):
    """A filter settled on a weld at y = 0, then the weld seen drifting sideways at `rate` mm
    per frame (faster lateral motion than the filter's random walk expects, no odometry of
    it). Returns the filter and, per drifting frame, (accepted, |estimate − truth|)."""
    rng = np.random.default_rng(seed)
    kf = WeldLineFilter(config, 150.0)
    for _ in range(30):
        kf.predict(1.5, 0.0)
        kf.update(150.0, rng.normal(0, 0.1), 0.8)
    rows = []
    for k in range(1, 25):
        kf.predict(1.5, 0.0, odometry=odometry)
        truth = rate * k
        ok = kf.update(150.0, truth + rng.normal(0, 0.1), 0.8)
        rows.append((ok, abs(kf.x[0] - truth)))
    return kf, rows


def test_gate_reacquires_a_steady_drift():
    """A prediction lagging a steady drift rejects the truth frame after frame while it moves
    on, so the rejected centres never agree on one offset; that they lie on one line in time
    restarts the filter after `trend_after` of them, not after `give_up_after`."""
    c = KalmanConfig()
    kf, rows = _drift(c)
    first = next(i for i, (ok, _) in enumerate(rows) if not ok)
    restart = first + c.trend_after - 1
    assert not any(ok for ok, _ in rows[first:restart]) and rows[restart][0]
    assert rows[restart][1] < 0.5  # restarted at the latest centre
    assert max(err for _, err in rows[restart + 1 :]) < 1.5  # and follows the drift since
    old, old_rows = _drift(KalmanConfig(trend_after=0))
    assert not any(ok for ok, _ in old_rows[first : first + c.give_up_after - 1])
    assert max(err for _, err in old_rows) > max(err for _, err in rows) + 2.0


def test_trend_restart_is_off_with_odometry():
    """With the motion measured, the same drift restarts the filter only as the gate did
    without the trend restart (`KalmanConfig.trend_after`: it cost the closed loop)."""
    kf, rows = _drift(KalmanConfig(), odometry=True)
    old, old_rows = _drift(KalmanConfig(trend_after=0), odometry=True)
    assert [ok for ok, _ in rows] == [ok for ok, _ in old_rows]
    assert kf.restarts == old.restarts
    _, blind = _drift(KalmanConfig())
    assert [ok for ok, _ in rows] != [ok for ok, _ in blind]


def _turn_onto_bar(config: KalmanConfig, seed: int = 6):
    """A filter settled on a weld along x_r, then the robot turns 90° left in place at a T
    whose bar passes through the robot's centre (its stripe at x_ref meets the bar at
    y_r = x_ref·cot ψ, ψ the turned angle, while |y_r| ≤ 60 mm), then drives 30 mm along
    the bar (on it: y_r = 0). Returns the filter and its offset errors along the bar."""
    rng = np.random.default_rng(seed)
    x_ref = 150.0
    kf = WeldLineFilter(config, x_ref)
    for _ in range(30):
        kf.predict(1.5, 0.0)
        kf.update(x_ref, rng.normal(0, 0.1), 0.8)
    step = 0.025  # rad per frame (0.5 rad/s at 20 fps)
    psi = 0.0
    while psi < math.pi / 2 - 1e-9:
        psi = min(psi + step, math.pi / 2)
        kf.predict(0.0, step if psi < math.pi / 2 else math.pi / 2 - (psi - step))
        y = x_ref / math.tan(psi)
        if abs(y) <= 60.0:
            kf.update(x_ref, y + rng.normal(0, 0.3), 0.5)
    errors = []
    for _ in range(20):
        kf.predict(1.5, 0.0)
        kf.update(x_ref, rng.normal(0, 0.3), 0.5)
        errors.append(abs(kf.x[0]))
    return kf, errors


def test_restart_after_a_turn_takes_the_new_welds_heading():
    """Re-acquiring the bar during the turn, the filter takes the bar's heading from the
    rejected centres' line (not the old weld's, 90° off), so the offset along the bar does
    not drift; with the old rule (keep the heading) it does."""
    kf, errors = _turn_onto_bar(KalmanConfig())
    assert kf.restarts >= 1
    assert abs(math.degrees(kf.x[1])) < 2.0
    assert max(errors) < 0.6
    old, old_errors = _turn_onto_bar(KalmanConfig(restart_heading_span_mm=0.0))
    assert abs(math.degrees(old.x[1])) > 10.0 or max(old_errors) > 1.0


def test_restart_keeps_the_heading_on_a_lateral_jump():
    """Centres that jump sideways on a straight pass keep the filter's heading (the line
    through them is short and agrees with it)."""
    rng = np.random.default_rng(8)
    kf = WeldLineFilter(KalmanConfig(), 150.0)
    theta = math.radians(2.0)
    for k in range(40):
        kf.predict(1.5, 0.0)
        kf.update(150.0, math.tan(theta) * 1.5 * k + rng.normal(0, 0.1), 0.8)
    for k in range(40, 46):
        before = kf.x[1]
        kf.predict(1.5, 0.0)
        kf.update(150.0, 6.0 + math.tan(theta) * 1.5 * k + rng.normal(0, 0.1), 0.8)
        if kf.restarts:
            break
    assert kf.restarts == 1
    assert kf.x[1] == before  # restarted with the heading it had


def test_default_rig_keeps_sigma_2(tracker, frames):
    # `cslx.runtime.stripe_width`: the default rig's clean stripes (FWHM ≈ 4.6 px) keep the
    # configured σ and the start-up program: nothing is compiled while tracking.
    for _, img, _ in frames:
        tracker.reset()
        tracker.step(img)
        assert tracker.sigma == 2.0 and max(tracker.stripe_width_px) < 5.2
    assert sum("compiled" in line for line in tracker.lines) == 1


def test_first_frame_check_is_bounded(tracker, frames, monkeypatch):
    """While no frame shows both stripes, the σ / colour check (≈ 27 ms) runs on the first 8
    frames after a reset, then on every 16th (`cslx.runtime.stripe_width.check_due`), and not
    again once a frame has measured both stripes."""
    import cslx.runtime.tracker as module

    checked = []
    widths = module.stripe_widths

    def counted(*args, **kwargs):
        checked.append(tracker.frame - 1)
        return widths(*args, **kwargs)

    monkeypatch.setattr(module, "stripe_widths", counted)
    tracker.reset()
    black = np.zeros(tracker.image_shape, np.uint8)
    for _ in range(40):
        assert tracker.step(black).status == "black frame"
    assert checked == [*range(8), 23, 39]
    for _ in range(30):
        tracker.step(frames[0][1], odometry=0.0)
    assert checked == [*range(8), 23, 39, 55]  # the stripes decided on frame 55
    assert min(tracker.stripe_width_px) > 0 and tracker.sigma == 2.0
    tracker.reset()


def test_green_laser_gets_bright_weights(tracker):
    """`cslx.runtime.stripe_colour`: R − G sees a green laser's stripes dark; the tracker
    switches to the searched space on the first frame (audit seed 8800, clean T scene) and
    its pipeline's Steger centres are then close to the truth (audit, σ 2: gross centres
    58 / 13 with R − G, 0 / 0 with the chosen (−1, 2, −1))."""
    import jax
    import jax.numpy as jnp

    from cslx.runtime.band_input import frame_input
    from cslx.segmentation import stripe_point_errors
    from cslx.segmentation.steger import steger_centres
    from cslx.sim import NUISANCES, random_pose, random_world, render_frame
    from cslx.sim.render import LASER_RGB

    sensor = default_sensor()
    rng = np.random.default_rng(8800)
    world = random_world("cross", rng)
    pose = random_pose(world, "cross", rng, sensor)
    nz = NUISANCES["clean"]._replace(laser_rgb=LASER_RGB["green"])
    img, gt = render_frame(sensor, world, pose, nz, 88000, scene_seed=8800)
    tracker.reset()
    obs = tracker.step(img, odometry=0.0)
    weights = tracker.weights
    tracker.reset()  # back to the configured program for the other tests
    assert weights != (1.0, -1.0, 0.0) and weights[1] > 0, weights
    assert obs.status == "ok"
    assert any("colour weights" in line for line in tracker.lines)

    config = tracker.config
    fill = jax.jit(frame_input, static_argnums=(1, 2, 3))
    gross = {}
    for w in ((1.0, -1.0, 0.0), weights):
        images = fill(jnp.asarray(img), w, jnp.float32, True)
        for axis, key in ((0, "h_xyz"), (1, "v_xyz")):
            c = steger_centres(
                images[axis], sigma=2.0, axis=axis, threshold=config.threshold, snr=config.snr
            )
            pos = np.where(np.asarray(c.valid), np.asarray(c.pos, float), np.nan)
            idx = np.arange(len(pos), dtype=float)
            uv = np.stack([idx, pos] if axis == 0 else [pos, idx], -1)
            err, _, n_gt, _ = stripe_point_errors(uv, gt[key], sensor, axis)
            gross[w, axis] = int(np.sum(err > 1.0))
            if w == weights:
                assert len(err) > 0.9 * n_gt and np.median(err) < 0.2  # audit: 0.12–0.14
    assert gross[(1.0, -1.0, 0.0), 0] + gross[(1.0, -1.0, 0.0), 1] >= 20, gross
    assert max(gross[weights, 0], gross[weights, 1]) <= 2, gross
