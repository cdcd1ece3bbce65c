"""Contact sheet of rendered frames: every nuisance preset × straight / T-intersection scenes.

Each scene is shown as rendered and again with its exact ground truth overlaid (horizontal
stripe centres in cyan, vertical in yellow), plus a row of laser variants (over-exposed red
core clipped to white, a 520 nm green laser). Compare with the paper's Figures 6, 7 and 18.

Writes `contact_sheet.png` in --out (default `results/`).
"""

from __future__ import annotations

import os
import time

import numpy as np

from experiments import common as C


def overlay(image: np.ndarray, gt: dict) -> np.ndarray:
    """Copy of `image` with the ground-truth centres drawn as 1-px dots."""
    out = image.copy()
    H, W = image.shape[:2]
    u = np.arange(W)
    ok = np.isfinite(gt["h_v"])
    v = np.round(gt["h_v"][ok]).astype(int)
    out[np.clip(v, 0, H - 1), u[ok]] = (0, 255, 255)
    r = np.arange(H)
    ok = np.isfinite(gt["v_u"])
    uu = np.round(gt["v_u"][ok]).astype(int)
    out[r[ok], np.clip(uu, 0, W - 1)] = (255, 255, 0)
    return out


def _label(img: np.ndarray, text: str) -> np.ndarray:
    import cv2

    img = np.array(img)
    cv2.putText(img, text, (8, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 0), 3, cv2.LINE_AA)
    cv2.putText(img, text, (8, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def main(seed: int = 3, scale: float = 0.5, out: str = str(C.RESULTS)) -> str:
    import cv2

    from cslx import sim as synth
    from cslx.sensor import default_sensor

    sensor = default_sensor()
    rows = []
    t0 = time.perf_counter()
    variants = [(name, synth.NUISANCES[name]) for name in synth.NUISANCES]
    variants.append(("red, power 10000 (core clips)", synth.Nuisance(laser_power=10000.0)))
    variants.append(
        (
            "green 520 nm, sunny",
            synth.NUISANCES["sunny"]._replace(laser_rgb=synth.LASER_RGB["green"]),
        )
    )
    for r, (name, nz) in enumerate(variants):
        tiles = []
        for kind in ("straight", "cross"):
            rng = np.random.default_rng([seed, r, kind == "cross"])
            world = synth.random_world(kind, rng)
            pose = synth.random_pose(world, kind, rng, sensor)
            img, gt = synth.render_frame(sensor, world, pose, nz, seed=seed + r)
            tiles.append(_label(img, f"{name} / {kind}"))
            tiles.append(_label(overlay(img, gt), "+ ground truth"))
        row = np.concatenate(tiles, axis=1)
        rows.append(cv2.resize(row, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA))
    sheet = np.concatenate(rows, axis=0)
    os.makedirs(out, exist_ok=True)
    out = os.path.join(out, "contact_sheet.png")
    cv2.imwrite(out, sheet[..., ::-1])
    print(f"wrote {out} ({len(variants) * 2} frames in {time.perf_counter() - t0:.1f} s)")
    return out


if __name__ == "__main__":
    args = C.parser(__doc__, 1, 3).parse_args()
    main(seed=args.seed, out=args.out)
