"""Track a weld from a camera, a video file or a directory of frames, and drive the robot.

Each frame goes through the runtime's per-frame loop (`cslx.runtime.loop.TrackingLoop`: the
compiled tracker, the path controller and, unless --dry-run, the serial link to the robot,
binary protocol of cslx/runtime/PROTOCOL.md). With --log, every frame read or lost gets one
CSV row (docs/contracts.md "Tracking log": frame,source,t_s,offset_mm,heading_deg,
bead_width_mm,bead_height_mm,junction,junction_x_mm,confidence,latency_ms, then extra
columns); a frame that cannot be decoded, or that a truncated video lost, still gets a row
with confidence 0. A status line (fps, offset, confidence) is kept on stderr.

Order of work: the arguments, the source (it must yield a first frame), the calibration and
the serial port are all checked before the 10–20 s compile, so a wrong input fails at once.
Ctrl-C, SIGTERM and SIGHUP send STOP to the robot and close the port and the log cleanly
(exit 130, 143, 129); during the compile they end the command at once with a message.

Time: in a dry run the frames' own timestamps (video position, a camera's grab time, or
frame index / --fps for a directory of frames); with a robot the measured time, since the robot
moves in real time. Odometry comes from the robot's telemetry when connected, else the
nominal speed (`cslx.config.Motion`).

--show DIR writes every frame with the tracker's overlay as a PNG into DIR (OpenCV here is
the headless build: it has no windows).
"""

from __future__ import annotations

import argparse
import gc
import math
import os
import signal
import sys
import threading
import time

from ..config import MOTION

NAME = "track"
HELP = "track the weld in a camera/video/image directory and drive the robot over serial"

#: Exit status of each signal that stops the command (128 + signal number).
_SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--source",
        required=True,
        help="camera index (0, 1, …), a video file, or a directory of frames (PNG, JPEG, BMP, "
        "TIFF; sorted by name)",
    )
    parser.add_argument("--calib", required=True, metavar="FILE", help="calibration JSON")
    link = parser.add_mutually_exclusive_group()
    link.add_argument("--port", help="serial port of the robot (device or pyserial URL)")
    link.add_argument("--dry-run", action="store_true", help="do not talk to a robot")
    parser.add_argument("--baud", type=int, default=115200, help="baud rate (default 115200)")
    parser.add_argument("--log", metavar="FILE.csv", help="write the tracking log here")
    parser.add_argument(
        "--show",
        metavar="DIR",
        help="write each frame with the tracker's overlay as a PNG into DIR",
    )
    parser.add_argument("--max-frames", type=int, default=None, metavar="N", help="stop after N")
    parser.add_argument(
        "--fps",
        type=float,
        default=MOTION.fps,
        help=f"frame rate of frame directories, and of videos without one ({MOTION.fps:g})",
    )
    parser.add_argument("--jax-cache", metavar="DIR", help="JAX persistent compilation cache")


class _Stop(BaseException):  # like KeyboardInterrupt: no `except Exception` swallows it
    """A signal asked the command to stop (Ctrl-C, SIGTERM, SIGHUP)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _raise_stop(signum, _frame):
    raise _Stop(signum)


class _Source:
    """Frames with timestamps: (name, rgb or None, t s or None) from OpenCV or an image folder.

    A video must give a first frame (else OSError: not a video OpenCV can read). A video
    that ends before its header's frame count, or fails mid-way, yields its missing frames
    as None (each gets a log row) and counts them in `lost`.
    """

    def __init__(self, spec: str, fps: float):
        import cv2

        self.cv2 = cv2
        self.files: list[str] | None = None
        self.cap = None
        self.fps = fps
        self.expected: int | None = None
        self.read = self.lost = 0
        self._first = None
        if os.path.isdir(spec):
            from ..images import IMAGE_EXTENSIONS, list_images

            self.files = list_images(spec)
            if not self.files:
                kinds = ", ".join(IMAGE_EXTENSIONS)
                raise OSError(f"{spec}: no image frames ({kinds}) in this directory")
            self.kind = "dir"
            self.expected = len(self.files)
            return
        target = int(spec) if spec.isdigit() else spec
        if isinstance(target, str):
            if not os.path.exists(target):
                raise OSError(f"{spec}: no such video file or directory")
            if not os.access(target, os.R_OK):
                raise OSError(f"{spec}: not readable")
        self.cap = cv2.VideoCapture(target)
        self.kind = "camera" if isinstance(target, int) else "video"
        if not self.cap.isOpened():
            raise OSError(f"{spec}: not a video (or camera) that OpenCV can open")
        ok, bgr = self.cap.read()
        if not ok or bgr is None:
            self.cap.release()
            raise OSError(f"{spec}: no frame could be decoded: not a video OpenCV can read")
        self._first = bgr
        if self.kind == "video":
            video_fps = self.cap.get(cv2.CAP_PROP_FPS)
            if video_fps and math.isfinite(video_fps) and video_fps > 0:
                self.fps = video_fps
            count = self.cap.get(cv2.CAP_PROP_FRAME_COUNT)
            if count and math.isfinite(count) and count > 0:
                self.expected = int(count)

    def __iter__(self):
        cv2 = self.cv2
        if self.files is not None:
            from ..images import read_rgb

            for i, path in enumerate(self.files):
                try:  # gray, alpha, 16-bit and EXIF-rotated frames as 8-bit RGB
                    rgb = read_rgb(path)
                except OSError:  # unreadable or truncated: the frame's row says "no frame"
                    rgb = None
                self.read += rgb is not None
                self.lost += rgb is None
                yield os.path.basename(path), rgb, i / self.fps
            return
        index, failures = 0, 0
        while True:
            if self._first is not None:
                ok, bgr, self._first = True, self._first, None
            else:
                ok, bgr = self.cap.read()
            name = f"{self.kind}:{index}"
            if self.kind == "camera":
                t = time.monotonic()
            else:
                t = index / self.fps
            if ok and bgr is not None:
                failures = 0
                self.read += 1
                if self.kind == "video":
                    ms = self.cap.get(cv2.CAP_PROP_POS_MSEC)
                    t = ms / 1000.0 if ms and math.isfinite(ms) and ms > 0 else t
                yield name, cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), t
                index += 1
                continue
            end = self.kind == "video" and (self.expected is None or index >= self.expected)
            if end:
                return
            failures += 1  # a lost frame (camera glitch, damaged or truncated video)
            if failures > 5:
                # give up: the rest of a video's frames are lost, each with its row
                while self.kind == "video" and index < self.expected:
                    self.lost += 1
                    yield f"{self.kind}:{index}", None, index / self.fps
                    index += 1
                return
            self.lost += 1
            yield name, None, t
            index += 1

    def close(self):
        if self.cap is not None:
            self.cap.release()


def _overlay(cv2, rgb, obs, path: str) -> None:
    if rgb is None:
        return
    bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    text = f"off {obs.offset_mm:+.1f} mm  hd {obs.heading_deg:+.1f} deg  conf {obs.confidence:.2f}"
    if obs.junction:
        text += f"  T at {obs.junction_x_mm:.0f} mm"
    cv2.putText(bgr, text, (10, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 255, 0), 2)
    cv2.putText(bgr, obs.status[:60], (10, 48), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 200, 255), 1)
    cv2.imwrite(path, bgr)


def _fail(msg: str) -> int:
    print(f"cslx track: {msg}", file=sys.stderr)
    return 2


def _check_args(args) -> str | None:
    """One line naming a bad argument, or None."""
    if not args.dry_run and not args.port:
        return "give --port PORT to drive a robot, or --dry-run"
    if not (math.isfinite(args.fps) and args.fps > 0):
        return f"--fps must be a positive number of frames per second, got {args.fps}"
    if args.max_frames is not None and args.max_frames < 1:
        return f"--max-frames must be at least 1, got {args.max_frames}"
    if args.baud <= 0:
        return f"--baud must be positive, got {args.baud}"
    if args.log:
        folder = os.path.dirname(os.path.abspath(args.log))
        if os.path.isdir(args.log):
            return f"--log {args.log}: is a directory; give a file name"
        if not os.path.isdir(folder):
            return f"--log {args.log}: the folder {folder} does not exist"
        if not os.access(folder, os.W_OK):
            return f"--log {args.log}: the folder {folder} is not writable"
    if args.show:
        if os.path.exists(args.show) and not os.path.isdir(args.show):
            return f"--show {args.show}: exists and is not a directory"
        parent = os.path.dirname(os.path.abspath(args.show))
        if not os.path.isdir(args.show) and not os.path.isdir(parent):
            return f"--show {args.show}: the folder {parent} does not exist"
    if not os.path.isfile(args.calib):
        what = "is a directory" if os.path.isdir(args.calib) else "no such file"
        return f"--calib {args.calib}: {what}"
    return None


def _compile(sensor, log):
    """Build the tracker (the long compile) in a thread; signals end the command at once."""
    from ..runtime.tracker import Tracker

    box: dict = {}

    def work():
        try:
            box["tracker"] = Tracker(sensor, log=log)
        except BaseException as e:  # noqa: BLE001 — handed to the main thread
            box["error"] = e

    worker = threading.Thread(target=work, name="cslx-compile", daemon=True)
    worker.start()
    while worker.is_alive():
        worker.join(0.1)  # the main thread stays interruptible
    if "error" in box:
        raise box["error"]
    return box["tracker"]


def run(args: argparse.Namespace) -> int:
    import logging

    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stderr)
    log = logging.getLogger("cslx.track")
    why = _check_args(args)
    if why:
        return _fail(why)
    previous = {}
    for name in _SIGNALS:
        if hasattr(signal, name):
            num = getattr(signal, name)
            previous[num] = signal.signal(num, _raise_stop)
    try:
        return _run(args, log)
    except _Stop as stop:
        # only reached before the loop started (the loop handles its own); the port, if
        # open, was closed with a STOP on the way out of `_run`
        print(
            f"\ncslx track: {stop} before tracking started: no command was sent; exiting",
            file=sys.stderr,
        )
        sys.stderr.flush()
        os._exit(128 + stop.signum)  # a compile in progress cannot be cancelled: leave now
    finally:
        for num, handler in previous.items():
            signal.signal(num, handler)


def _run(args, log) -> int:
    # Start-up allocates ≈ 10⁶ long-lived objects (JAX, the tracker): the cyclic garbage
    # collector would scan them again and again while they load. It stays off until the
    # tracker is built; then they move to the permanent generation (`gc.freeze`), so the
    # collections between frames no longer scan them either (issue 13, start-up).
    gc.disable()
    try:
        return _run_collected(args, log)
    finally:
        gc.enable()


def _run_collected(args, log) -> int:
    from ..runtime import ControllerConfig, PathController, RobotLink
    from ..runtime.loop import TrackingLoop, TrackLog
    from ..sensor import CalibrationError, load_sensor

    try:
        source = _Source(args.source, args.fps)
    except OSError as e:
        return _fail(str(e))
    link = None
    try:
        try:
            sensor = load_sensor(args.calib)
        except CalibrationError as e:
            return _fail(str(e))
        if args.show:
            os.makedirs(args.show, exist_ok=True)
        if not args.dry_run:
            try:
                link = RobotLink(args.port, args.baud).open()
            except (OSError, ValueError) as e:
                return _fail(f"--port {args.port}: {e}")
            log.info(f"robot link open on {args.port}")
        if args.jax_cache:
            from ..environment import set_compile_cache

            set_compile_cache(args.jax_cache)
        tracker = _compile(sensor, log)
        gc.freeze()
        gc.enable()
        # the turn at a T ends on the offset observed where the stripe crosses the robot's
        # axis (`Tracker.lookahead_mm`: x_ref on a rig whose stripe runs straight across)
        ctrl = PathController(ControllerConfig(lookahead_mm=tracker.lookahead_mm))
        return _loop(args, source, tracker, link, ctrl, TrackingLoop, TrackLog)
    finally:
        source.close()
        if link is not None:
            link.close(stop=True)  # idempotent: sends STOP(OPERATOR) if still open


def _loop(args, source, tracker, link, controller, TrackingLoop, TrackLog) -> int:
    tlog = TrackLog(args.log) if args.log else None
    loop = TrackingLoop(tracker, controller, link, log=tlog)
    live = link is not None
    n = 0
    stopped = None
    t_start = time.perf_counter()
    try:
        for name, rgb, t in source:
            step = loop.step(rgb, name, t=None if live else t)
            obs = step.observation
            if args.show:
                stem = os.path.splitext(name.replace(":", "_"))[0]
                _overlay(source.cv2, rgb, obs, os.path.join(args.show, f"{n:06d}_{stem}.png"))
            n += 1
            fps = n / max(time.perf_counter() - t_start, 1e-9)
            sys.stderr.write(
                f"\r{n} frames  {fps:5.1f} fps  offset {obs.offset_mm:+7.2f} mm  "
                f"conf {obs.confidence:.2f}  {obs.status[:30]:30s}"
            )
            sys.stderr.flush()
            if args.max_frames is not None and n >= args.max_frames:
                break
    except (_Stop, KeyboardInterrupt) as e:
        stopped = e.signum if isinstance(e, _Stop) else signal.SIGINT
        what = signal.Signals(stopped).name
        sys.stderr.write(f"\n{what}: stopping the robot\n" if live else f"\n{what}: stopping\n")
    finally:
        if link is not None:
            link.close(stop=True)  # sends STOP(OPERATOR) and waits briefly for its ACK
        if tlog is not None:
            tlog.close()
        sys.stderr.write(f"\n{n} frames processed\n")
        if source.lost:
            sys.stderr.write(
                f"warning: {source.lost} of {source.read + source.lost} frames could not be "
                f"read (each has a log row with confidence 0)\n"
            )
        if source.kind == "video" and source.expected and n < source.expected and not stopped:
            if args.max_frames is None or n < args.max_frames:
                sys.stderr.write(
                    f"warning: the video ended after {n} of {source.expected} frames\n"
                )
    return 128 + int(stopped) if stopped else 0
