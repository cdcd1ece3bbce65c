"""The unified segmentation interface, the metrics and `cslx extract` on synthetic cross stripes."""

import csv
import json

import cv2
import jax.numpy as jnp
import numpy as np
import pytest

from cslx.cli import main
from cslx.segmentation import METHODS, centres_to_pixels, extract, stripe_errors
from cslx.segmentation.steger import Centres
from cslx.sensor import default_sensor, save_sensor, triangulate

H, W = 120, 160


def cross_image(hc=50.3, vc=90.7, s=2.0, seed=0, h=H, w=W):
    """Red laser cross (Gaussian profile, slight green leakage) on grey noise, uint8 RGB."""
    rng = np.random.default_rng(seed)
    v = np.arange(h, dtype=float)[:, None]
    u = np.arange(w, dtype=float)[None, :]
    laser = np.maximum(np.exp(-0.5 * ((v - hc) / s) ** 2), np.exp(-0.5 * ((u - vc) / s) ** 2))
    grey = 60.0 + rng.normal(0, 4, (h, w))
    rgb = np.stack([grey + 150 * laser, grey + 20 * laser, grey + 5 * laser], axis=-1)
    return np.clip(np.round(rgb), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("method", METHODS)
def test_every_method_finds_both_stripes(method):
    img = cross_image()
    hc, vc = 50.3, 90.7
    opts = {"med_options": {"L": 21}} if method == "med" else {}
    h = extract(img, method, space="r-g", stripe="h", **opts)
    v = extract(img, method, space="r-g", stripe="v", **opts)
    assert isinstance(h, Centres) and len(h.pos) == W and len(v.pos) == H
    hu = np.abs(np.arange(W) - vc) > 8  # columns away from the crossing
    vr = np.abs(np.arange(H) - hc) > 8
    hv, vv = np.asarray(h.valid)[hu], np.asarray(v.valid)[vr]
    assert hv.mean() > 0.9 and vv.mean() > 0.9
    # 8-bit noise of σ 4 grey levels on a 130-level stripe: a few hundredths of a pixel for
    # the sub-pixel methods; 0.25 px leaves room for the split-and-merge approximations.
    assert np.nanmax(np.abs(np.asarray(h.pos)[hu][hv] - hc)) < 0.25
    assert np.nanmax(np.abs(np.asarray(v.pos)[vr][vv] - vc)) < 0.25


def test_spaces_and_bad_arguments():
    img = cross_image()
    for space in ("r", "gray", "auto", "2,-1,-1", (1.0, -1.0, 0.0)):
        c = extract(img, "steger", space=space, stripe="h")
        assert np.asarray(c.valid).mean() > 0.8
    mono = img[..., 0].astype(float) - img[..., 1]
    a = extract(mono, "steger", stripe="h")
    b = extract(img, "steger", space="r-g", stripe="h")
    np.testing.assert_allclose(np.asarray(a.pos), np.asarray(b.pos), atol=1e-3, equal_nan=True)
    with pytest.raises(ValueError, match="method"):
        extract(img, "sobel")
    with pytest.raises(ValueError, match="stripe"):
        extract(img, "cm", stripe="x")
    with pytest.raises(ValueError, match="colour space"):
        extract(img, "cm", space="hsv")


def test_centres_to_pixels():
    c = Centres(np.array([3.5, 7.0, 1.0]), np.array([True, False, True]), np.ones(3))
    h = centres_to_pixels(c, "h")
    np.testing.assert_array_equal(h[[0, 2]], [[0, 3.5], [2, 1.0]])
    assert np.isnan(h[1]).all()
    v = centres_to_pixels(c, "v")
    np.testing.assert_array_equal(v[[0, 2]], [[3.5, 0], [1.0, 2]])


def test_stripe_errors_counts_against_ground_truth():
    sensor = default_sensor(jnp.float64)
    n = 200
    u = np.arange(n, dtype=float) + 200
    v = 240.0 + 0.05 * u
    uv_true = np.stack([u, v], axis=1)
    gt = np.array(triangulate(sensor, jnp.asarray(uv_true), 0))
    gt[:10] = np.nan  # no stripe in the first 10 columns
    est = uv_true.copy()
    est[20:30] = np.nan  # 10 missed columns
    est[50, 1] += 0.5  # half a pixel off
    est[60, 1] += 30.0  # a gross outlier
    r = stripe_errors(est, gt, sensor, 0)
    assert r["n_gt"] == 190 and r["n_matched"] == 180
    assert r["detection_rate"] == pytest.approx(180 / 190)
    assert r["false_positives"] == 10
    assert r["gross_outliers"] == 1
    assert r["median_mm"] < 1e-6
    # independent: the 3-D error of the half-pixel column
    half = np.linalg.norm(np.asarray(triangulate(sensor, jnp.asarray(est[50]), 0)) - gt[50])
    big = np.linalg.norm(np.asarray(triangulate(sensor, jnp.asarray(est[60]), 0)) - gt[60])
    assert r["mean_mm"] == pytest.approx((half + big) / 180, rel=1e-6)
    assert r["mean_px"] == pytest.approx((0.5 + 30.0) / 180, rel=1e-4)
    with pytest.raises(ValueError, match="gt_xyz"):
        stripe_errors(est, gt[:5], sensor, 0)


def _read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_cli_extract_writes_the_centre_csv(tmp_path, capsys):
    good = tmp_path / "cross.png"
    cv2.imwrite(str(good), cross_image(seed=1)[..., ::-1])
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), cross_image(seed=2)[..., ::-1] * 0 + 60)
    broken = tmp_path / "broken.png"
    broken.write_bytes(b"not a png")
    out = tmp_path / "centres.csv"
    rc = main(
        ["extract", str(good), str(broken), str(blank), "--method", "steger", "--out", str(out)]
    )
    err = capsys.readouterr().err
    assert rc == 1
    assert "broken.png" in err and "blank.png" in err and "no stripe" in err
    rows = _read_csv(out)
    assert list(rows[0]) == ["image", "stripe", "u", "v"]
    assert {r["image"] for r in rows} == {str(good)}
    h = [r for r in rows if r["stripe"] == "h"]
    v = [r for r in rows if r["stripe"] == "v"]
    assert len({r["u"] for r in h}) == len(h) > 0.8 * W  # at most one per column
    assert len({r["v"] for r in v}) == len(v) > 0.8 * H
    hv = np.array([float(r["v"]) for r in h if abs(float(r["u"]) - 90.7) > 8])
    assert np.abs(hv - 50.3).max() < 0.1


def test_cli_extract_with_calibration(tmp_path, capsys):
    sensor = default_sensor()  # 640×480
    calib = tmp_path / "sensor.json"
    save_sensor(sensor, calib)
    img = tmp_path / "cross.png"
    cv2.imwrite(str(img), cross_image(240.2, 330.6, h=480, w=640)[..., ::-1])
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), cross_image()[..., ::-1])
    out = tmp_path / "c.csv"
    rc = main(
        ["extract", str(img), str(small), "--method", "cm", "--stripe", "h",
         "--calib", str(calib), "--out", str(out)]
    )  # fmt: skip
    err = capsys.readouterr().err
    assert rc == 1 and "small.png" in err and "640×480" in err
    rows = _read_csv(out)
    assert list(rows[0]) == ["image", "stripe", "u", "v", "x", "y", "z"]
    assert {r["stripe"] for r in rows} == {"h"}
    uv = np.array([[float(r["u"]), float(r["v"])] for r in rows])
    xyz = np.array([[float(r[k]) for k in "xyz"] for r in rows])
    ref = np.asarray(triangulate(sensor, jnp.asarray(uv), 0))
    np.testing.assert_allclose(xyz, ref, atol=2e-3)  # CSV keeps 4 decimals of float32 values
    assert main(["extract", str(img), "--space", "hsv", "--out", str(out)]) == 2
    assert "colour space" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"K": 1}))
    assert main(["extract", str(img), "--calib", str(bad), "--out", str(out)]) == 2


@pytest.mark.slow
@pytest.mark.parametrize("method", ["steger", "med", "cm"])
def test_rendered_cross_frames(method):
    # Rendered ground truth (cslx.sim): both stripes found on most columns/rows, with a
    # sub-millimetre median error. Slow: the renderer compiles for about a minute.
    from cslx.sim import render_dataset

    images, gt, sensor = render_dataset("cross", "clean", n_frames=2, seed=101)
    for k in range(len(images)):
        for stripe, key, plane in (("h", "h_xyz", 0), ("v", "v_xyz", 1)):
            c = extract(images[k], method, space="r-g", stripe=stripe)
            r = stripe_errors(centres_to_pixels(c, stripe), gt[key][k], sensor, plane)
            assert r["detection_rate"] > 0.9, r
            assert r["median_mm"] < 0.5, r
