"""Track a weld from a camera, a video file or a directory of PNG frames, and drive the robot.

Each frame goes through the compiled tracker (`cslx.runtime.Tracker`): the observation and the
path controller's velocity command (`cslx.runtime.PathController`) are sent to the robot over
the serial link (`cslx.runtime.RobotLink`, binary protocol of cslx/robot/PROTOCOL.md) unless
--dry-run is given. With --log, every frame read gets one CSV row (docs/contracts.md tracking log:
frame,source,t_s,offset_mm,heading_deg,bead_width_mm,bead_height_mm,junction,junction_x_mm,
confidence,latency_ms, then extra columns); a frame that cannot be decoded still gets a row
with confidence 0. A status line (fps, offset, confidence) is kept on stderr. Ctrl-C sends
STOP to the robot and closes the port and the log cleanly. Odometry for the tracker comes
from the robot's telemetry when connected, else the nominal speed.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import sys
import time

NAME = "track"
HELP = "track the weld in a camera/video/PNG directory and drive the robot over serial"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--source",
        required=True,
        help="camera index (0, 1, …), a video file, or a directory of PNG frames (sorted)",
    )
    parser.add_argument("--calib", required=True, metavar="FILE", help="calibration JSON")
    link = parser.add_mutually_exclusive_group()
    link.add_argument("--port", help="serial port of the robot (device or pyserial URL)")
    link.add_argument("--dry-run", action="store_true", help="do not talk to a robot")
    parser.add_argument("--baud", type=int, default=115200, help="baud rate (default 115200)")
    parser.add_argument("--log", metavar="FILE.csv", help="write the tracking log here")
    parser.add_argument("--show", action="store_true", help="show frames with the stripes")
    parser.add_argument("--max-frames", type=int, default=None, metavar="N", help="stop after N")
    parser.add_argument(
        "--fps", type=float, default=20.0, help="nominal frame rate for PNG directories (20)"
    )
    parser.add_argument("--jax-cache", metavar="DIR", help="JAX persistent compilation cache")


class _Source:
    """Frames from OpenCV VideoCapture or a sorted directory of PNGs: (name, rgb or None)."""

    def __init__(self, spec: str, fps: float):
        import cv2

        self.cv2 = cv2
        self.files: list[str] | None = None
        self.cap = None
        self.fps = fps
        if os.path.isdir(spec):
            names = sorted(f for f in os.listdir(spec) if f.lower().endswith(".png"))
            if not names:
                raise OSError(f"{spec}: no PNG frames in this directory")
            self.files = [os.path.join(spec, f) for f in names]
            self.kind = "dir"
        else:
            target = int(spec) if spec.isdigit() else spec
            if isinstance(target, str) and not os.path.exists(target):
                raise OSError(f"{spec}: no such video file or directory")
            self.cap = cv2.VideoCapture(target)
            if not self.cap.isOpened():
                raise OSError(f"{spec}: OpenCV cannot open this camera or video")
            self.fps = self.cap.get(cv2.CAP_PROP_FPS) or fps
            self.kind = "camera" if isinstance(target, int) else "video"
        self.index = 0

    def __iter__(self):
        cv2 = self.cv2
        if self.files is not None:
            for path in self.files:
                bgr = cv2.imread(path, cv2.IMREAD_COLOR)
                rgb = None if bgr is None else cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
                yield os.path.basename(path), rgb
            return
        failures = 0
        while True:
            ok, bgr = self.cap.read()
            name = f"{self.kind}:{self.index}"
            self.index += 1
            if not ok:
                if self.kind == "video":
                    return  # end of file
                failures += 1  # a camera glitch: log the frame, give up after a few
                if failures > 5:
                    return
                yield name, None
                continue
            failures = 0
            yield name, cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)

    def close(self):
        if self.cap is not None:
            self.cap.release()


def _fmt(x) -> str:
    if isinstance(x, float):
        return "nan" if math.isnan(x) else f"{x:.4f}"
    return str(x)


def _show(cv2, rgb, obs):
    if rgb is None:
        return
    bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    text = f"off {obs.offset_mm:+.1f} mm  conf {obs.confidence:.2f}" + (
        f"  T at {obs.junction_x_mm:.0f} mm" if obs.junction else ""
    )
    cv2.putText(bgr, text, (10, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (0, 255, 0), 2)
    cv2.imshow("cslx track", bgr)
    cv2.waitKey(1)


def run(args: argparse.Namespace) -> int:
    import logging

    from ..runtime import PathController, RobotLink
    from ..runtime.tracker import LOG_FIELDS, Observation, Tracker
    from ..sensor import CalibrationError

    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stderr)
    log = logging.getLogger("cslx.track")
    if not args.dry_run and not args.port:
        print("cslx track: give --port PORT to drive a robot, or --dry-run", file=sys.stderr)
        return 2
    try:
        source = _Source(args.source, args.fps)
    except OSError as e:
        print(f"cslx track: {e}", file=sys.stderr)
        return 2
    try:
        if args.jax_cache:
            from ..environment import set_compile_cache

            set_compile_cache(args.jax_cache)
        tracker = Tracker.from_calibration(args.calib, log=log)
    except CalibrationError as e:
        print(f"cslx track: {e}", file=sys.stderr)
        source.close()
        return 2

    link = None
    if not args.dry_run:
        try:
            link = RobotLink(args.port, args.baud).open()
        except (OSError, ValueError) as e:
            print(f"cslx track: {e}", file=sys.stderr)
            source.close()
            return 2
    controller = PathController()
    log_file = writer = None
    if args.log:
        fields = [*Observation(0, 0.0).log_row(""), "v_mm_s", "omega_rad_s", "state"]
        assert tuple(fields[: len(LOG_FIELDS)]) == LOG_FIELDS
        log_file = open(args.log, "w", newline="", encoding="utf-8")  # noqa: SIM115
        writer = csv.DictWriter(log_file, fieldnames=fields)
        writer.writeheader()
    dt_nominal = 1.0 / (source.fps if source.fps and source.fps > 0 else args.fps)
    n = 0
    interrupted = False
    last_pose = None
    t_start = time.perf_counter()
    try:
        for name, rgb in source:
            odometry = None
            if link is not None and link.latest_state is not None:
                st = link.latest_state
                if last_pose is not None:
                    dx, dy = st.x_mm - last_pose[0], st.y_mm - last_pose[1]
                    c, s = math.cos(last_pose[2]), math.sin(last_pose[2])
                    d = dx * c + dy * s
                    dh = math.atan2(
                        math.sin(st.heading_rad - last_pose[2]),
                        math.cos(st.heading_rad - last_pose[2]),
                    )
                    odometry = (d, dh)
                last_pose = (st.x_mm, st.y_mm, st.heading_rad)
            obs = tracker.step(rgb, dt=dt_nominal, odometry=odometry)
            cmd = controller.update(
                dt_nominal,
                obs.offset_mm,
                obs.heading_deg,
                obs.confidence,
                obs.junction,
                obs.junction_x_mm,
            )
            if link is not None:
                link.send_observation(obs.to_message())
                link.send_command(cmd.v_mm_s, cmd.omega_rad_s)
            if log_file is not None:
                row = obs.log_row(name)
                row.update(v_mm_s=cmd.v_mm_s, omega_rad_s=cmd.omega_rad_s, state=cmd.state.value)
                writer.writerow({k: _fmt(v) for k, v in row.items()})
                log_file.flush()
            if args.show:
                _show(source.cv2, rgb, obs)
            n += 1
            fps = n / max(time.perf_counter() - t_start, 1e-9)
            sys.stderr.write(
                f"\r{n} frames  {fps:5.1f} fps  offset {obs.offset_mm:+7.2f} mm  "
                f"conf {obs.confidence:.2f}  {obs.status[:30]:30s}"
            )
            sys.stderr.flush()
            if args.max_frames is not None and n >= args.max_frames:
                break
    except KeyboardInterrupt:
        interrupted = True
        sys.stderr.write("\ninterrupted: stopping the robot\n")
    finally:
        if link is not None:
            link.close(stop=True)  # sends STOP(OPERATOR) and waits briefly for its ACK
        if log_file is not None:
            log_file.close()
        source.close()
        if args.show:
            source.cv2.destroyAllWindows()
        sys.stderr.write(f"\n{n} frames processed\n")
    return 130 if interrupted else 0
