"""Smoke runs of the experiment scripts (Table 6 at --quick, one figure), < 60 s in all.

They check that the scripts run end to end and write well-formed outputs whose numbers are
consistent with the library's own metric (`cslx.segmentation.stripe_errors`), not the numbers
themselves (those are the experiments' results).
"""

import csv
import math
import pathlib

import numpy as np
import pytest

EXPERIMENTS = pathlib.Path(__file__).resolve().parents[2] / "experiments"


def test_point_errors_match_stripe_errors():
    """The pooled per-point errors of the experiments equal `stripe_errors` on one frame."""
    from cslx.segmentation import stripe_errors
    from cslx.sensor import default_sensor
    from experiments import common as C

    sensor = default_sensor()
    image, gt = C.frame_at("straight", "glare", 5, 1, sensor)  # the frame of the next test
    for stripe in ("h", "v"):
        uv = C.centres_for(image, "cm", C.SPACES["r-g"], stripe)
        uv[::7] = np.nan  # some misses, so the matched subset matters
        ref = stripe_errors(uv, gt[C.STRIPE_GT[stripe]], sensor, C.STRIPE_PLANE[stripe])
        pool = C.Pool()
        pool.add(*C.point_errors(uv, gt[C.STRIPE_GT[stripe]], sensor, C.STRIPE_PLANE[stripe]))
        s = pool.summary()
        assert s["n_matched"] == ref["n_matched"] and s["n_gt"] == ref["n_gt"]
        for k in ("mean_mm", "median_mm", "p95_mm", "mean_px"):
            assert s[k] == pytest.approx(ref[k], rel=1e-6, abs=1e-9), k
        assert s["gross_outliers"] == ref["gross_outliers"]


def test_frame_at_matches_render_dataset():
    """`frame_at` reproduces frame i of `render_dataset` without rendering the others."""
    from cslx import sim as synth
    from experiments import common as C

    images, gt, _ = synth.render_dataset("straight", "glare", 2, seed=5)
    image, g1 = C.frame_at("straight", "glare", 5, 1)
    np.testing.assert_array_equal(image, images[1])
    np.testing.assert_array_equal(g1["h_v"], gt["h_v"][1])


def test_table6_quick(tmp_path):
    from experiments import table6_segmentation as T

    rows = T.main(quick=True, out=str(tmp_path))
    with open(tmp_path / "table6_segmentation.csv", encoding="utf-8") as f:
        csv_rows = list(csv.DictReader(f))
    assert len(csv_rows) == len(rows)
    pooled = [r for r in rows if r["condition"] == "all"]
    # Every paper row is present, for both stripes and both spaces.
    assert {(r["stripe"], r["space"], r["method"]) for r in pooled} >= set(T.PAPER)
    for r in pooled:
        assert r["time_calls"] >= 1 and r["time_ms"] > 0
        assert 0.0 <= r["detection_rate"] <= 1.0
        if r["n_matched"]:
            assert r["median_mm"] <= r["p95_mm"] + 1e-12
            assert math.isfinite(r["mean_mm"])
    md = (tmp_path / "table6_segmentation.md").read_text(encoding="utf-8")
    assert "Claim (i)" in md and "Claim (ii)" in md and "git" in md


def test_fig07_writes_png(tmp_path):
    from experiments import fig07_colour_spaces as F

    rows = F.main(out=str(tmp_path))
    assert (tmp_path / "fig07_colour_spaces.png").stat().st_size > 10_000
    by = {r["space"]: r for r in rows}
    # Kurtosis is the search's criterion: its pick scores at least as high as R, gray, R−G.
    pick = next(v for k, v in by.items() if k.startswith("kurtosis pick"))
    assert pick["kurtosis"] >= max(by[k]["kurtosis"] for k in ("R", "gray", "R−G")) - 1e-3


def test_flat_wall_line_residuals_undistort_before_the_line_fit():
    """A straight line in the undistorted image, distorted by the lens, fits with zero residual
    once undistorted; added orthogonal noise comes back as its RMS."""
    import jax.numpy as jnp

    from cslx.sensor import default_sensor
    from cslx.sensor.camera import distort, normalized_to_pixel
    from experiments.flat_wall import line_residuals

    camera = default_sensor().camera
    t = np.linspace(-0.35, 0.35, 400)
    xy = np.stack([t, 0.12 + 0.3 * t], axis=1)  # a tilted straight line (normalized)
    uv = np.asarray(normalized_to_pixel(distort(jnp.asarray(xy), camera.dist), camera), float)
    bent = np.abs(np.polyfit(uv[:, 0], uv[:, 1], 1, full=True)[1][0] / len(uv)) ** 0.5
    assert bent > 0.05  # the lens bends it in pixels
    assert np.sqrt(np.mean(line_residuals(uv, camera) ** 2)) < 0.01
    noise = np.random.default_rng(0).normal(0, 0.2, len(uv))
    normal = np.array([-0.3, 1.0]) / np.hypot(0.3, 1.0)  # ≈ the image normal of the line
    rms = np.sqrt(np.mean(line_residuals(uv + noise[:, None] * normal, camera) ** 2))
    assert rms == pytest.approx(0.2, rel=0.15)


def test_tracking_sequence_verdicts_name_the_worst_run():
    from experiments.tracking_sequences import GOALS, verdicts

    good = dict(
        seed=1,
        placement="beside",
        nuisance="clean",
        estimate_pct=100.0,
        offset_mean_mm=0.1,
        offset_max_mm=0.5,
        heading_mean_deg=0.3,
        t_recall_pct=95.0,
        t_false=0,
    )
    bad = dict(good, nuisance="sunny", heading_mean_deg=0.8, t_false=2)
    lines = verdicts([good, bad])
    assert len(lines) == 2 + len(GOALS)
    by_goal = {line.split(" | ")[0].lstrip("| "): line for line in lines[2:]}
    assert by_goal["heading error mean ≤ 0.5°"].endswith("**missed** |")
    assert "1 of 2 | 0.8 (beside sunny 1)" in by_goal["heading error mean ≤ 0.5°"]
    assert "1 of 2 | 2 (beside sunny 1)" in by_goal["no T reported where it is not"]
    assert by_goal["offset error max ≤ 1 mm"].endswith("**met** |")


def test_figure22_and_the_demo_leave_out_the_same_start_transient():
    """One documented default (`SETTLE_S`) for run_closed_loop, Figure 22 and the demo."""
    import inspect

    from cslx.sim.closed_loop import SETTLE_S, run_closed_loop
    from experiments.fig22_tracking import DEFAULTS

    assert inspect.signature(run_closed_loop).parameters["settle_s"].default == SETTLE_S
    assert DEFAULTS["settle_s"] == SETTLE_S
    demo = (EXPERIMENTS.parent / "cslx" / "cli" / "demo.py").read_text(encoding="utf-8")
    assert "leave out the first 5 s" not in demo and "SETTLE_S" in demo
