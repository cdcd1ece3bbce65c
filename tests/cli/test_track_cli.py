"""`cslx track` with real files, a real pseudo-terminal robot and real signals.

The tracking log follows docs/contracts.md; bad inputs are refused before the compile with
one line and exit 2; SIGTERM / SIGHUP / Ctrl-C stop the robot like the end of the run.
"""

import csv
import logging
import math
import os
import pathlib
import signal
import subprocess
import sys
import threading
import time

import cv2
import numpy as np
import pytest

from cslx.cli import main
from cslx.runtime.protocol import Stop, StopReason, VelocityCommand
from cslx.runtime.tracker import LOG_FIELDS
from cslx.sensor import default_sensor
from cslx.sim import RobotPose, random_pose, random_world, render_frame, write_dataset
from cslx.sim.robot import RobotSimulator, SimulatorConfig

ROOT = pathlib.Path(__file__).resolve().parents[2]
HEADER = (
    "frame,source,t_s,offset_mm,heading_deg,bead_width_mm,bead_height_mm,junction,"
    "junction_x_mm,confidence,latency_ms"
)


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """Three rendered frames along a straight weld (PNG folder + sensor.json) and truth."""
    sensor = default_sensor()
    rng = np.random.default_rng(5)
    world = random_world("straight", rng)
    x, y, th = random_pose(world, "straight", rng, sensor)[:3]
    images, gts = [], []
    for i in range(3):
        pose = RobotPose(x + 1.5 * i * np.cos(th), y + 1.5 * i * np.sin(th), th)
        img, g = render_frame(sensor, world, pose, "clean", seed=i, scene_seed=0)
        images.append(img)
        gts.append(g)
    gt = {k: np.stack([g[k] for g in gts]) for k in gts[0]}
    folder = tmp_path_factory.mktemp("video")
    names = write_dataset(folder, np.stack(images), gt, sensor)
    return dict(folder=folder, names=names, gt=gt, images=images, calib=folder / "sensor.json")


@pytest.fixture(scope="module")
def cache(jax_cache):
    """The test session's JAX compile cache, shared with the commands' subprocesses (the
    tracker's program is compiled once for every test here and in the other worker)."""
    return jax_cache


def _rows(path):
    return list(csv.DictReader(open(path, encoding="utf-8")))


def test_track_dry_run_writes_log(data, tmp_path, capsys, caplog, cache):
    caplog.set_level(logging.INFO, logger="cslx.track")
    src = tmp_path / "video"
    src.mkdir()
    for name in data["names"]:
        os.symlink(data["folder"] / name, src / name)
    (src / "frame_99999.png").write_bytes(b"not a png")  # sorted last: an unreadable frame
    log, show = tmp_path / "track.csv", tmp_path / "overlay"
    argv = ["track", "--source", str(src), "--calib", str(data["calib"]), "--dry-run"]
    rc = main([*argv, "--log", str(log), "--show", str(show), "--jax-cache", cache])
    assert rc == 0
    text = log.read_text().splitlines()
    assert text[0].startswith(HEADER + ",")
    assert tuple(text[0].split(",")[: len(LOG_FIELDS)]) == LOG_FIELDS
    rows = _rows(log)
    assert [r["source"] for r in rows] == [*data["names"], "frame_99999.png"]
    assert [int(r["frame"]) for r in rows] == [0, 1, 2, 3]
    # a PNG folder's timestamps: frame index / --fps (20)
    assert [float(r["t_s"]) for r in rows] == pytest.approx([0.0, 0.05, 0.1, 0.15])
    for r, true_offset in zip(rows[:3], data["gt"]["offset_mm"], strict=True):
        assert abs(float(r["offset_mm"]) - true_offset) < 1.0
        assert 0 < float(r["confidence"]) <= 1 and float(r["latency_ms"]) > 0
    bad = rows[3]
    assert float(bad["confidence"]) == 0.0 and math.isnan(float(bad["offset_mm"]))
    assert bad["status"] == "no frame"
    err = capsys.readouterr().err
    assert "fps" in err and "4 frames processed" in err
    assert "1 of 4 frames could not be read" in err
    assert "compiled the 640×480 pipeline" in caplog.text and "frame 3: no frame" in caplog.text
    # --show: one overlay picture per decoded frame, readable by OpenCV
    pictures = sorted(show.iterdir())
    assert len(pictures) == 3
    assert cv2.imread(str(pictures[0])).shape == data["images"][0].shape


@pytest.mark.parametrize(
    "extra, expected",
    [
        (["--fps", "0"], "--fps must be a positive"),
        (["--fps", "-5"], "--fps must be a positive"),
        (["--fps", "nan"], "--fps must be a positive"),
        (["--max-frames", "0"], "--max-frames must be at least 1"),
        (["--log", "{tmp}/missing/log.csv"], "does not exist"),
        (["--log", "{tmp}"], "is a directory"),
        (["--show", "{tmp}/file.txt"], "not a directory"),
    ],
)
def test_bad_arguments_refused_before_any_work(data, tmp_path, capsys, caplog, extra, expected):
    caplog.set_level(logging.INFO, logger="cslx.track")
    (tmp_path / "file.txt").write_text("x")
    extra = [e.format(tmp=tmp_path) for e in extra]
    argv = ["track", "--source", str(data["folder"]), "--calib", str(data["calib"])]
    assert main([*argv, "--dry-run", *extra]) == 2
    err = capsys.readouterr().err
    assert expected in err and len(err.strip().splitlines()) == 1
    assert "Traceback" not in err and "compiled" not in caplog.text
    assert not (tmp_path / "missing").exists()


def test_bad_sources_and_calibration(data, tmp_path, capsys):
    calib = str(data["calib"])
    text = tmp_path / "notes.txt"
    text.write_text("this is not a video\n")
    cases = [
        (["--source", str(text), "--calib", calib], "not a video"),
        (["--source", str(tmp_path / "nope.mp4"), "--calib", calib], "no such video"),
        (["--source", str(tmp_path), "--calib", calib], "no image frames"),
        (["--source", str(data["folder"]), "--calib", str(tmp_path)], "is a directory"),
        (["--source", str(data["folder"]), "--calib", str(text)], "notes.txt"),
    ]
    for argv, expected in cases:
        assert main(["track", *argv, "--dry-run"]) == 2, argv
        err = capsys.readouterr().err
        assert expected in err and "Traceback" not in err, (argv, err)
    assert main(["track", "--source", str(data["folder"]), "--calib", calib]) == 2
    assert "--dry-run" in capsys.readouterr().err


def test_missing_port_refused_before_the_compile(data, tmp_path, capsys, caplog):
    caplog.set_level(logging.INFO, logger="cslx.track")
    argv = ["track", "--source", str(data["folder"]), "--calib", str(data["calib"])]
    t0 = time.monotonic()
    assert main([*argv, "--port", str(tmp_path / "ttyNOPE")]) == 2
    err = capsys.readouterr().err
    assert "--port" in err and "ttyNOPE" in err and "Traceback" not in err
    assert "compiled" not in caplog.text
    assert time.monotonic() - t0 < 10.0  # no compile happened (it takes 10–40 s here)


def _video(path, images, fps=20.0):
    writer = cv2.VideoWriter(
        str(path), cv2.CAP_FFMPEG, cv2.VideoWriter_fourcc(*"MJPG"), fps, (640, 480)
    )
    assert writer.isOpened()
    for img in images:
        writer.write(cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
    writer.release()


def test_truncated_video_warns_and_logs_every_frame(data, tmp_path, capsys, cache):
    full = tmp_path / "full.mkv"
    _video(full, data["images"] * 4)  # 12 frames
    blob = full.read_bytes()
    cut = tmp_path / "cut.mkv"
    cut.write_bytes(blob[: len(blob) // 2])
    count = int(cv2.VideoCapture(str(cut)).get(cv2.CAP_PROP_FRAME_COUNT))
    assert count == 12  # the container still announces all of them
    log = tmp_path / "log.csv"
    argv = ["track", "--source", str(cut), "--calib", str(data["calib"]), "--dry-run"]
    assert main([*argv, "--log", str(log), "--jax-cache", cache]) == 0
    err = capsys.readouterr().err
    rows = _rows(log)
    assert len(rows) == count and [r["source"] for r in rows] == [f"video:{i}" for i in range(12)]
    lost = [r for r in rows if r["status"] == "no frame"]
    read = len(rows) - len(lost)
    assert 0 < read < count and all(float(r["confidence"]) == 0.0 for r in lost)
    assert f"{len(lost)} of {count} frames could not be read" in err
    t = [float(r["t_s"]) for r in rows]
    assert t[1] == pytest.approx(0.05, abs=1e-3) and all(
        b > a for a, b in zip(t, t[1:], strict=False)
    )


def test_drives_the_robot_over_a_pty_and_stops_at_the_end(data, tmp_path, cache):
    cfg = SimulatorConfig(realtime=True, command_timeout_s=5.0)
    with RobotSimulator(config=cfg) as sim:
        argv = ["track", "--source", str(data["folder"]), "--calib", str(data["calib"])]
        assert main([*argv, "--port", sim.port, "--jax-cache", cache]) == 0
        kinds = [type(m) for _, _, m in sim.received]
        assert kinds.count(VelocityCommand) == 3
        stops = [m for _, _, m in sim.received if isinstance(m, Stop)]
        assert stops and stops[-1].reason == StopReason.OPERATOR
        last_stop = max(i for i, k in enumerate(kinds) if k is Stop)
        assert last_stop > max(i for i, k in enumerate(kinds) if k is VelocityCommand)


def _spawn(argv, cache):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(
        [sys.executable, "-m", "cslx", *argv, "--jax-cache", cache],
        cwd=ROOT,
        env=env,
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        text=True,
    )
    lines: list[str] = []

    def read():
        for line in proc.stderr:
            lines.append(line)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    return proc, lines, reader


def _many_frames(data, folder, n):
    folder.mkdir()
    for i in range(n):
        name = data["names"][i % len(data["names"])]
        os.symlink(data["folder"] / name, folder / f"f{i:05d}.png")


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_signal_sends_stop_and_leaves_a_complete_log(data, tmp_path, cache, sig):
    _many_frames(data, tmp_path / "frames", 2000)
    log = tmp_path / "log.csv"
    cfg = SimulatorConfig(realtime=True, command_timeout_s=5.0)
    with RobotSimulator(config=cfg) as sim:
        argv = ["track", "--source", str(tmp_path / "frames"), "--calib", str(data["calib"])]
        proc, lines, reader = _spawn([*argv, "--port", sim.port, "--log", str(log)], cache)
        try:
            deadline = time.monotonic() + 240
            while time.monotonic() < deadline and proc.poll() is None:
                if log.exists() and len(log.read_text().splitlines()) > 5:
                    break
                time.sleep(0.2)
            assert proc.poll() is None, "".join(lines)
            commands_before = sum(isinstance(m, VelocityCommand) for _, _, m in sim.received)
            assert commands_before > 0
            proc.send_signal(sig)
            rc = proc.wait(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
        reader.join(5)
        err = "".join(lines)
        assert rc == 128 + sig, err
        assert "Traceback" not in err and f"{signal.Signals(sig).name}: stopping" in err
        stops = [m for _, _, m in sim.received if isinstance(m, Stop)]
        assert stops and stops[-1].reason == StopReason.OPERATOR
        last = max(i for i, (_, _, m) in enumerate(sim.received) if isinstance(m, Stop))
        assert not any(isinstance(m, VelocityCommand) for _, _, m in sim.received[last:])
    rows = _rows(log)
    n = int(next(line for line in lines if "frames processed" in line).split()[0])
    assert len(rows) == n and all(len(r) == len(rows[0]) and None not in r for r in rows)


def test_ctrl_c_during_the_compile_exits_cleanly(data, tmp_path):
    cfg = SimulatorConfig(realtime=True, command_timeout_s=5.0)
    fresh = str(tmp_path / "empty-cache")  # a compile that really takes a while
    with RobotSimulator(config=cfg) as sim:
        argv = ["track", "--source", str(data["folder"]), "--calib", str(data["calib"])]
        proc, lines, reader = _spawn([*argv, "--port", sim.port], fresh)
        try:
            deadline = time.monotonic() + 120
            while time.monotonic() < deadline and not any("link open" in x for x in lines):
                time.sleep(0.05)
            assert any("link open" in x for x in lines), "".join(lines)
            time.sleep(0.5)
            t0 = time.monotonic()
            proc.send_signal(signal.SIGINT)
            rc = proc.wait(timeout=30)
            took = time.monotonic() - t0
        finally:
            if proc.poll() is None:
                proc.kill()
        reader.join(5)
        err = "".join(lines)
        assert rc == 130, err
        assert "before tracking started" in err and "Traceback" not in err
        assert not any("compiled the" in x for x in lines)  # it did not wait for the compile
        assert took < 10.0
        assert not any(isinstance(m, VelocityCommand) for _, _, m in sim.received)
        assert any(isinstance(m, Stop) for _, _, m in sim.received)
