"""Closed-loop weld tracking: tracker, controller and a simulated robot over a real pty.

The simulated differential-drive robot (`cslx.sim.robot.RobotSimulator`, on the far end of a
real pseudo-terminal, lock-step mode) starts beside a weld (the stem) that ends at a
T-intersection with a crossing weld (the bar). Every step:

1. the frame its camera sees from the simulator's true pose is rendered with the nuisances
   (`cslx.sim.render_image`, default rig);
2. the runtime's one per-frame loop (`cslx.runtime.loop.TrackingLoop`, the same object
   `cslx track` drives) runs the compiled tracker with the odometry from the robot's
   telemetry received over the link, the path controller (follow, approach the junction,
   turn 90° left in place, follow the bar) and sends the observation and the
   VELOCITY_COMMAND, which the robot acknowledges; the frame's time is the simulated time;
3. the simulator integrates 1/fps s of motion.

Lock-step: rendering a frame takes about a second on the CPU, so simulated time advances only
when the loop says so, and the link's watchdog timeouts are raised accordingly.

Tracking error (the paper: < 2 mm on average): the distance from the point where the
horizontal stripe crosses the robot's x_r axis (the controlled look-ahead point) to the true
centre line of the weld being followed, |offset|·cos(heading), in frames where that point is
on the followed weld (not while the stripe is past the end of the stem, and not during the
turn). The tracker's estimation error (estimated − true offset) is reported beside it.

`experiments/fig22_tracking.py` runs the long version and writes Figure 22; `cslx demo`
runs a short one.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..config import MOTION, Motion

__all__ = ["SETTLE_S", "plot_closed_loop", "run_closed_loop"]

#: The start transient, s, that the `steady_*` statistics leave out (the controller's response
#: to the designed start error, 4 mm and 3° ≈ 11.85 mm at the look-ahead point): that error
#: fell below 0.5 mm after 1.1 s in Figure 22's clean and sunny runs at fb7bf8c, and the stem
#: is left ≈ 2.3 s after a start 220 mm before the T, so the former 5 s left no stem frame in
#: `steady_*`. `cslx demo` and `experiments/fig22_tracking.py` use this default.
SETTLE_S = 1.5


def _world(seed: int):
    from .render import make_world

    rng = np.random.default_rng([seed, 22])
    w0, h0 = rng.uniform(12, 20), rng.uniform(1.5, 2.5)
    w1, h1 = rng.uniform(12, 20), rng.uniform(1.5, 2.5)
    welds = [((0.0, 0.0), math.pi, w0, h0, True), ((0.0, 0.0), math.pi / 2, w1, h1, False)]
    return make_world(welds, rng=rng), (w0, h0, w1, h1)


def _truth(world, pose, sensor, follow: int, widths) -> dict:
    """True offset/heading of the followed weld at the stripe and whether it is there."""
    from .scene import RobotPose
    from .truth import true_weld_line

    line = true_weld_line(world, RobotPose(*pose), sensor, follow, 1 - follow)
    x, y, th = pose
    # world position of the stripe's crossing with the followed weld
    px = x + line["stripe_x_mm"] * math.cos(th) - line["offset_mm"] * math.sin(th)
    py = y + line["stripe_x_mm"] * math.sin(th) + line["offset_mm"] * math.cos(th)
    if follow == 0:  # the stem ends at the junction (origin), minus the bar's half-width
        on_weld = px < -(widths[2] / 2 + 5.0)
    else:
        on_weld = True
    err = abs(line["offset_mm"] * math.cos(math.radians(line["heading_deg"])))
    return dict(
        true_offset_mm=line["offset_mm"],
        true_heading_deg=line["heading_deg"],
        true_junction_x_mm=line["junction_x_mm"],
        tracking_error_mm=err,
        on_weld=bool(on_weld and abs(line["heading_deg"]) < 45.0),
        crossing_x=px,
        crossing_y=py,
    )


def _wait(cond, timeout=2.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.0005)
    return cond()


def run_closed_loop(
    n_frames: int = 60,
    seed: int = 0,
    nuisance: str = "clean",
    *,
    fps: float = MOTION.fps,
    start_before_mm: float = 250.0,
    start_offset_mm: float = 4.0,
    start_heading_deg: float = 3.0,
    turn_rate: float = 0.5,
    settle_s: float = SETTLE_S,
    after_turn_frames: int | None = None,
    tracker=None,
    sensor=None,
    progress: bool = False,
    log=None,
) -> dict:
    """Drive the simulated robot along the stem and through the T for `n_frames` frames.

    Args:
        n_frames: frames (steps of 1/fps s).
        seed: picks the bead sizes, texture and noise.
        nuisance: `cslx.sim.NUISANCES` preset for every frame.
        start_before_mm: distance from the robot's reference point to the junction at start.
        start_offset_mm, start_heading_deg: initial lateral / heading error of the robot.
        turn_rate: the controller's turning rate at the T, rad/s.
        settle_s: the "steady" statistics leave out the first settle_s seconds (the
            controller's response to the initial error; default `SETTLE_S`, why there):
            `steady_*` over the rest of the run, `stem_steady_*` over the rest of the
            stem only; `after_turn_*` cover every counted frame on the crossing weld, the
            re-acquisition after the turn included (nothing of the turn's transient is
            left out there).
        after_turn_frames: end the run this many frames after the turn was completed
            (None: run all `n_frames`).
        tracker: a `Tracker` for ``sensor`` to reuse (compiled once), else built here.
        sensor: the rig that renders the frames (`cslx.sensor.Sensor`; default
            `cslx.sensor.default_sensor`), e.g. a rolled projector's.

    Returns:
        dict with `rows` (per-frame dicts), `welds` (bead sizes), and the summary numbers:
        mean/max/p95 tracking error, mean/max estimation error (frames on the weld), frames
        counted, turns completed, tracker compile time, median step latency (ms),
        tracker fps, loop fps without and with rendering.
    """
    from ..runtime import ControllerConfig, PathController, RobotLink, State, Tracker
    from ..runtime.loop import LoopConfig, TrackingLoop
    from ..sensor import default_sensor
    from .render import render_image
    from .robot import RobotSimulator, SimulatorConfig
    from .scene import RobotPose

    sensor = default_sensor() if sensor is None else sensor
    world, sizes = _world(seed)
    if tracker is None:
        tracker = Tracker.from_calibration(sensor, log=log or (lambda s: None))
    tracker.reset()
    # the offset is observed where the stripe crosses the weld: its lever is the stripe's
    # x_r on the robot's axis (`Tracker.lookahead_mm`; x_ref on the default rig)
    config = ControllerConfig(turn_rate=turn_rate, lookahead_mm=tracker.lookahead_mm)
    controller = PathController(config)
    start = (-start_before_mm, start_offset_mm, math.radians(start_heading_deg))
    cfg = SimulatorConfig(realtime=False, command_timeout_s=1e6, seed=seed)
    dt = 1.0 / fps
    rows: list[dict] = []
    t_loop = []
    t_render = []
    follow = 0
    turned_at = None
    turn_start = None  # (frame, controller's x_j, true axis distance to the bar's centre line)
    it = range(n_frames)
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc=f"closed loop ({nuisance})")
    with (
        RobotSimulator(pose=start, config=cfg) as sim,
        RobotLink(sim.port, stall_timeout_s=1e6, low_conf_timeout_s=1e6) as link,
    ):
        loop = TrackingLoop(
            tracker,
            controller,
            link,
            config=LoopConfig(motion=Motion(MOTION.speed_mm_s, fps), ack_timeout_s=2.0),
        )
        for i in it:
            pose = sim.pose()
            t0 = time.perf_counter()
            # the image only: the stripes' ground truth is not needed here (true_weld_line is)
            img = render_image(
                sensor, world, RobotPose(*pose), nuisance, seed=seed * 100003 + i, scene_seed=seed
            )
            t1 = time.perf_counter()
            # telemetry of the last advance (sent by the robot over the pty)
            _wait(
                lambda: (
                    link.latest_state is not None and link.latest_state.t_s >= sim.sim_time - 1e-6
                )
            )
            done = loop.step(img, f"sim:{i}", t=sim.sim_time)
            obs, cmd = done.observation, done.command
            sim.advance(dt)
            t2 = time.perf_counter()
            if turn_start is None and cmd.state is State.TURN:
                # x_j is dead-reckoned to the pose after this step's motion: compare it with
                # that pose's distance along its axis to the bar's centre line (x_w = 0)
                xa, _, tha = sim.pose()
                turn_start = (i, controller.junction_x, -xa / math.cos(tha))
            t_render.append(t1 - t0)
            t_loop.append(t2 - t1)
            if controller.turns_completed > 0:
                if follow == 0:
                    turned_at = i
                follow = 1
            truth = _truth(world, pose, sensor, follow, sizes)
            counted = (
                truth["on_weld"]
                and controller.state is not State.TURN
                and cmd.state is not State.TURN
            )
            rows.append(
                dict(
                    frame=i,
                    t_s=i * dt,
                    x_mm=pose[0],
                    y_mm=pose[1],
                    heading_deg=math.degrees(pose[2]),
                    followed=follow,
                    state=cmd.state.value,
                    v_mm_s=cmd.v_mm_s,
                    omega_rad_s=cmd.omega_rad_s,
                    est_offset_mm=obs.offset_mm,
                    est_heading_deg=obs.heading_deg,
                    confidence=obs.confidence,
                    junction=int(obs.junction),
                    junction_x_mm=obs.junction_x_mm,
                    latency_ms=obs.latency_ms,
                    status=obs.status,
                    counted=int(counted),
                    estimation_error_mm=obs.offset_mm - truth["true_offset_mm"],
                    nuisance=str(nuisance),
                    **truth,
                )
            )
            if after_turn_frames is not None and turned_at is not None:
                if i - turned_at >= after_turn_frames:
                    break
    counted = [r for r in rows if r["counted"]]
    steady = np.array([r["tracking_error_mm"] for r in counted if r["t_s"] >= settle_s])
    stem = np.array(
        [r["tracking_error_mm"] for r in counted if r["t_s"] >= settle_s and r["followed"] == 0]
    )
    bar = np.array([r["tracking_error_mm"] for r in counted if r["followed"] == 1])
    err = np.array([r["tracking_error_mm"] for r in counted])
    est = np.array([r["estimation_error_mm"] for r in counted])
    est = est[np.isfinite(est)]
    lat = np.array([r["latency_ms"] for r in rows[1:]])
    nan = math.nan
    # where the robot stopped at the T (issue 12: the turn is in place, so the reference
    # point's x_w after the turn, + = past the bar's centre line, becomes the look-ahead
    # point's offset on the bar) and the controller's junction distance error when the turn
    # started (+ = x_j too far: the robot goes on past the T)
    stop_x = rows[turned_at]["x_mm"] if turned_at is not None else nan
    xj_err = nan
    if turn_start is not None and turn_start[1] is not None:
        xj_err = float(turn_start[1] - turn_start[2])
    return dict(
        rows=rows,
        welds=dict(
            stem_width_mm=sizes[0],
            stem_height_mm=sizes[1],
            bar_width_mm=sizes[2],
            bar_height_mm=sizes[3],
        ),
        n_frames=len(rows),
        n_counted=len(counted),
        blind_stops=controller.blind_stops,
        mean_error_mm=float(err.mean()) if err.size else nan,
        p95_error_mm=float(np.percentile(err, 95)) if err.size else nan,
        max_error_mm=float(err.max()) if err.size else nan,
        n_steady=int(steady.size),
        steady_mean_error_mm=float(steady.mean()) if steady.size else nan,
        steady_max_error_mm=float(steady.max()) if steady.size else nan,
        stem_steady_mean_error_mm=float(stem.mean()) if stem.size else nan,
        stem_steady_max_error_mm=float(stem.max()) if stem.size else nan,
        after_turn_mean_error_mm=float(bar.mean()) if bar.size else nan,
        after_turn_max_error_mm=float(bar.max()) if bar.size else nan,
        mean_abs_estimation_error_mm=float(np.abs(est).mean()) if est.size else nan,
        max_abs_estimation_error_mm=float(np.abs(est).max()) if est.size else nan,
        turns_completed=controller.turns_completed,
        turn_start_frame=turn_start[0] if turn_start is not None else None,
        turn_stop_x_mm=float(stop_x),
        turn_junction_x_error_mm=xj_err,
        junction_frames=int(sum(r["junction"] for r in rows)),
        compile_s=tracker.compile_s,
        step_median_ms=float(np.median(lat)) if lat.size else nan,
        tracker_fps=float(1000.0 / np.median(lat)) if lat.size else nan,
        loop_fps=float(1.0 / np.median(t_loop)) if t_loop else nan,
        loop_fps_with_render=float(1.0 / np.median(np.add(t_loop, t_render))) if t_loop else nan,
    )


def plot_closed_loop(result: dict, path: str | None = None, axes=None, label: str = "") -> None:
    """Figure 22: the welds' centre lines and the robot's trail, and the error over time.

    Draws into `axes` (a pair) when given, else a new figure saved to `path`.
    """
    import matplotlib

    if axes is None:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = result["rows"]
    w = result["welds"]
    if axes is None:
        fig, (a, b) = plt.subplots(1, 2, figsize=(13, 5.2))
    else:
        fig, (a, b) = None, axes
    # the look-ahead point is drawn where it is on the followed weld (during the turn and
    # past the stem's end the stripe line meets the weld's extension far away)
    on = [r for r in rows if r["counted"]]
    xs = [r["x_mm"] for r in rows] + [r["crossing_x"] for r in on]
    ys = [r["y_mm"] for r in rows] + [r["crossing_y"] for r in on]
    lo_x, hi_x = min(xs) - 40, max(max(xs) + 40, w["bar_width_mm"])
    lo_y, hi_y = min(ys) - 40, max(ys) + 40
    a.fill_between([lo_x, 0], -w["stem_width_mm"] / 2, w["stem_width_mm"] / 2, color="0.85")
    a.fill_betweenx([lo_y, hi_y], -w["bar_width_mm"] / 2, w["bar_width_mm"] / 2, color="0.85")
    a.plot([lo_x, 0], [0, 0], "k-", lw=1, label="true weld centre lines")
    a.plot([0, 0], [lo_y, hi_y], "k-", lw=1)
    a.plot(
        [r["x_mm"] for r in rows], [r["y_mm"] for r in rows], "b-", label="robot reference point"
    )
    a.plot(
        [r["crossing_x"] for r in on],
        [r["crossing_y"] for r in on],
        "r.",
        ms=2,
        label="stripe crossing (look-ahead)",
    )
    a.set_aspect("equal")
    a.set_xlim(lo_x, hi_x)
    a.set_ylim(lo_y, hi_y)
    a.set_xlabel("x_w (mm)")
    a.set_ylabel("y_w (mm)")
    a.set_title(f"{label}Welds (grey: beads) and the robot's trail", fontsize=9)
    a.legend(loc="best", fontsize=8)
    t = np.array([r["t_s"] for r in rows])
    err = np.array([r["tracking_error_mm"] if r["counted"] else np.nan for r in rows])
    est = np.array([abs(r["estimation_error_mm"]) if r["counted"] else np.nan for r in rows])
    b.plot(t, err, "b-", label="tracking error (look-ahead point to centre line)")
    b.plot(t, est, "r-", lw=0.8, label="|estimated − true offset|")
    turn = np.array([r["state"] == "turn" for r in rows])
    if turn.any():
        b.axvspan(t[turn].min(), t[turn].max(), color="0.9", label="turn at the T")
    b.axhline(2.0, color="k", ls="--", lw=0.8, label="paper: 2 mm")
    b.set_xlabel("t (s)")
    b.set_ylabel("mm")
    b.set_title(
        f"{label}mean {result['mean_error_mm']:.2f}, p95 {result['p95_error_mm']:.2f}, "
        f"max {result['max_error_mm']:.2f} mm; turns {result['turns_completed']}",
        fontsize=9,
    )
    b.legend(fontsize=7)
    if fig is not None:
        fig.tight_layout()
        from ..files import atomic_path

        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=120)
        plt.close(fig)
