"""The one per-frame loop (tracker → controller → link) over a real pseudo-terminal.

A compiled `Tracker` on rendered frames, the `PathController`, a `RobotLink` and the pty
`RobotSimulator` in lock-step: the safety behaviours are checked on the robot's side.
"""

import csv
import math

import numpy as np
import pytest

from cslx.runtime import ControllerConfig, PathController, RobotLink, State, Tracker
from cslx.runtime.loop import LoopConfig, TrackingLoop, TrackLog, odometry_between
from cslx.sensor import default_sensor
from cslx.sim import RobotPose, random_pose, random_world, render_image
from cslx.sim.robot import RobotSimulator, SimulatorConfig

DT = 0.05


@pytest.fixture(scope="module")
def tracker():
    return Tracker.from_calibration(default_sensor(), log=lambda s: None)


@pytest.fixture(scope="module")
def frames():
    """Four frames along a straight weld, 1.5 mm apart."""
    sensor = default_sensor()
    rng = np.random.default_rng(77)
    world = random_world("straight", rng)
    x, y, th = random_pose(world, "straight", rng, sensor)[:3]
    out = []
    for i in range(4):
        pose = RobotPose(x + 1.5 * i * np.cos(th), y + 1.5 * i * np.sin(th), th)
        out.append(render_image(sensor, world, pose, "clean", seed=i, scene_seed=1))
    return out


def _rig(tracker, config=None):
    sim = RobotSimulator(config=SimulatorConfig(realtime=False, command_timeout_s=1e6)).start()
    link = RobotLink(sim.port, stall_timeout_s=1e6, low_conf_timeout_s=1e6).open()
    tracker.reset()
    ctrl = PathController(config)
    loop = TrackingLoop(tracker, ctrl, link, config=LoopConfig(ack_timeout_s=2.0))
    return sim, link, loop


def _wait_state(link, sim):
    # up to 10 s: on a loaded 2-core CI machine the telemetry thread can lag by seconds
    for _ in range(2000):
        st = link.latest_state
        if st is not None and st.t_s >= sim.sim_time - 1e-9:
            return
        import time

        time.sleep(0.005)


def _drive(sim, link, loop, images):
    """Step the loop on each image (None: lost) at 20 fps of simulated time."""
    out = []
    for img in images:
        _wait_state(link, sim)
        out.append(loop.step(img, t=sim.sim_time))
        sim.advance(DT)
    return out


@pytest.mark.parametrize("state", [State.FOLLOW, State.APPROACH_JUNCTION])
@pytest.mark.parametrize("bad", ["lost", "black"])
def test_robot_stops_within_blind_time_on_bad_frames(tracker, frames, state, bad):
    c = ControllerConfig()
    sim, link, loop = _rig(tracker, c)
    try:
        steps = _drive(sim, link, loop, frames * 10)  # 2 s of good frames: moving
        assert steps[-1].command.v_mm_s > 10.0 and sim.state().left_mm_s > 10.0
        if state is State.APPROACH_JUNCTION:  # a confirmed T 200 mm ahead
            loop.controller.state, loop.controller.junction_x = state, 200.0
        black = np.zeros_like(frames[0])
        bad_frames = [None if bad == "lost" else black] * 30
        t_bad = sim.sim_time
        steps = _drive(sim, link, loop, bad_frames)
        for s in steps:
            assert s.observation.confidence == 0.0 and not s.observation.stripe_ok
        # never faster than before, and stopped once blind_stop_s of measured time passed
        v = [s.command.v_mm_s for s in steps]
        assert all(b <= a + 1e-9 for a, b in zip(v, v[1:], strict=False))
        n_blind = math.ceil(c.blind_stop_s / DT)
        assert all(x == 0.0 for x in v[n_blind:])
        # on the robot: wheels at rest and the pose frozen, < blind_stop_s + one frame later
        _wait_state(link, sim)
        assert sim.state().left_mm_s == 0.0 and sim.state().right_mm_s == 0.0
        pose = sim.pose()
        sim.advance(1.0)
        assert sim.pose() == pose
        assert loop.controller.state is state  # the manoeuvre is kept for when it sees again
        assert sim.sim_time - t_bad > c.blind_stop_s
    finally:
        link.close()
        sim.stop()


def test_dt_from_timestamps_and_one_log_row_per_frame(tracker, frames, tmp_path):
    tracker.reset()
    path = tmp_path / "log.csv"
    with TrackLog(str(path)) as log:
        loop = TrackingLoop(tracker, PathController(), log=log)
        times = [10.0, 10.05, 10.15, 10.15, 10.12, 10.4]  # repeated and backwards stamps
        images = [frames[0], frames[1], None, frames[2], frames[3], None]
        steps = [
            loop.step(img, f"f{i}", t=t)
            for i, (img, t) in enumerate(zip(images, times, strict=True))
        ]
    dts = [s.dt for s in steps]
    nominal = 1.0 / LoopConfig().motion.fps
    # first frame and non-advancing stamps: nominal; otherwise the measured difference
    assert dts[0] == pytest.approx(nominal)
    assert dts[1] == pytest.approx(0.05) and dts[2] == pytest.approx(0.10)
    assert dts[3] == pytest.approx(nominal) and dts[4] == pytest.approx(nominal)
    assert dts[5] == pytest.approx(10.4 - (10.15 + 2 * nominal))
    rows = list(csv.DictReader(path.open()))
    assert [r["source"] for r in rows] == [f"f{i}" for i in range(6)]
    assert [float(r["dt_s"]) for r in rows] == pytest.approx(dts, abs=1e-4)
    t = [float(r["t_s"]) for r in rows]
    assert t[0] == 0.0 and all(b > a for a, b in zip(t, t[1:], strict=False))
    for r in (rows[2], rows[5]):  # lost frames: a row with confidence 0
        assert float(r["confidence"]) == 0.0 and r["status"] == "no frame"
    assert loop.lost == 2 and loop.frames == 6


def test_odometry_from_telemetry_reaches_the_tracker(tracker, frames):
    sim, link, loop = _rig(tracker)
    try:
        steps = _drive(sim, link, loop, frames * 5)
        # the robot's own motion, from its telemetry over the pty, frame to frame
        moved = [s.odometry[0] for s in steps[2:]]
        assert all(m >= 0.0 for m in moved) and sum(moved) > 10.0
    finally:
        link.close()
        sim.stop()


def test_odometry_between():
    d, dh = odometry_between((0.0, 0.0, math.pi / 2), (0.0, 3.0, math.pi / 2 + 0.1))
    assert d == pytest.approx(3.0) and dh == pytest.approx(0.1)
    d, dh = odometry_between((1.0, 1.0, math.pi - 0.05), (0.0, 1.0, -math.pi + 0.05))
    assert d == pytest.approx(math.cos(0.05)) and dh == pytest.approx(0.1)
