"""`cslx extract --method med`: band MED on batches (issue 13), rows in input order."""

from __future__ import annotations

import csv

import cv2
import numpy as np

from cslx.cli import main


def _cross_png(path, seed, h_row, v_col):
    rng = np.random.default_rng(seed)
    H, W = 240, 320
    rows, cols = np.arange(H)[:, None], np.arange(W)[None, :]
    red = 150 * np.exp(-0.5 * ((rows - h_row) / 2.0) ** 2)
    red = red + 150 * np.exp(-0.5 * ((cols - v_col) / 2.0) ** 2)
    red *= 1 + 0.2 * rng.standard_normal((H, W))
    light = np.broadcast_to(40 + 20 * np.cos(np.pi * rows / H), (H, W))
    rgb = np.clip(np.stack([red + light, light + 5, light], -1), 0, 255).astype(np.uint8)
    cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))


def test_extract_med_bands_in_order_with_a_failed_image(tmp_path, capsys, monkeypatch):
    import cslx.cli.extract as ext

    monkeypatch.setattr(ext, "MED_BATCH", 2)  # 3 good images: one full batch, one padded
    truth = {}
    paths = []
    for k, (r, c) in enumerate([(100.3, 150.6), (120.7, 170.2), (90.5, 200.4)]):
        p = tmp_path / f"f{k}.png"
        _cross_png(p, k, r, c)
        truth[str(p)] = (r, c)
        paths.append(str(p))
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not a png")
    paths.insert(1, str(bad))
    # a monochrome camera's frame between them: full-frame MED in its gray values (R − G
    # would be zero), its rows between the band batches' rows
    gray = tmp_path / "gray.png"
    cv2.imwrite(str(gray), cv2.imread(paths[-1])[..., 2])
    truth[str(gray)] = truth[paths[-1]]
    paths.insert(3, str(gray))
    out = tmp_path / "c.csv"
    assert main(["extract", *paths, "--method", "med", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert f"{bad}: not a readable image; skipped" in err and "4 of 5 images" in err
    assert "1 of 5 images are grayscale" in err
    rows = list(csv.DictReader(out.open()))
    order = list(dict.fromkeys(r["image"] for r in rows))
    assert order == [p for p in paths if p != str(bad)]
    for p, (r, c) in truth.items():
        h = [float(x["v"]) for x in rows if x["image"] == p and x["stripe"] == "h"]
        v = [float(x["u"]) for x in rows if x["image"] == p and x["stripe"] == "v"]
        assert len(h) > 0.9 * 320 and len(v) > 0.9 * 240
        assert abs(np.median(h) - r) < 0.1 and abs(np.median(v) - c) < 0.1
