"""`cslx track --dry-run` on a rendered PNG directory writes the docs/contracts.md tracking log."""

import csv
import logging
import math

import numpy as np

from cslx.cli import main
from cslx.runtime.tracker import LOG_FIELDS
from cslx.sensor import default_sensor
from cslx.sim import RobotPose, random_pose, random_world, render_frame, write_dataset

HEADER = (
    "frame,source,t_s,offset_mm,heading_deg,bead_width_mm,bead_height_mm,junction,"
    "junction_x_mm,confidence,latency_ms"
)


def test_track_dry_run_writes_log(tmp_path, capsys, caplog):
    caplog.set_level(logging.INFO, logger="cslx.track")
    # three frames of a robot driving along a straight weld at 1.5 mm per frame
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
    frames = np.stack(images)
    gt = {k: np.stack([g[k] for g in gts]) for k in gts[0]}
    data = tmp_path / "video"
    names = write_dataset(data, frames, gt, sensor)
    (data / "frame_99999.png").write_bytes(b"not a png")  # sorted last: an unreadable frame
    log = tmp_path / "track.csv"
    rc = main(
        [
            "track",
            "--source",
            str(data),
            "--calib",
            str(data / "sensor.json"),
            "--dry-run",
            "--log",
            str(log),
        ]
    )
    assert rc == 0
    text = log.read_text().splitlines()
    assert text[0].startswith(HEADER + ",")
    assert tuple(text[0].split(",")[: len(LOG_FIELDS)]) == LOG_FIELDS
    rows = list(csv.DictReader(log.open()))
    assert [r["source"] for r in rows] == [*names, "frame_99999.png"]
    assert [int(r["frame"]) for r in rows] == [0, 1, 2, 3]
    for r, true_offset in zip(rows[:3], gt["offset_mm"], strict=True):
        assert abs(float(r["offset_mm"]) - true_offset) < 1.0
        assert 0 < float(r["confidence"]) <= 1 and float(r["latency_ms"]) > 0
    bad = rows[3]
    assert float(bad["confidence"]) == 0.0 and math.isnan(float(bad["offset_mm"]))
    assert bad["status"] == "no frame"
    err = capsys.readouterr().err
    assert "fps" in err and "4 frames processed" in err
    assert "compiled the 640×480 pipeline" in caplog.text and "frame 3: no frame" in caplog.text


def test_track_needs_port_or_dry_run(tmp_path, capsys):
    assert main(["track", "--source", str(tmp_path), "--calib", "x.json"]) == 2
    assert "--dry-run" in capsys.readouterr().err
    np.testing.assert_equal(
        main(["track", "--source", str(tmp_path), "--calib", "x.json", "--dry-run"]), 2
    )
    assert "no PNG frames" in capsys.readouterr().err
