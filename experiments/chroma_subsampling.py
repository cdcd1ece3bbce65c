"""Real-camera formats (issue 11): the linked detector on chroma-subsampled frames.

Rendered frames (`cslx.sim`) are full-resolution RGB; real cameras rarely are. Webcams stream
MJPEG (JPEG, YCbCr 4:2:0) or YUYV (4:2:2), photos are JPEG 4:2:0. For a red laser the R − G
signal the colour search picks is pure chroma (R − G = 0.344 Cb + 2.116 Cr in JFIF YCbCr),
so in a subsampled frame the stripe's profile across it is sampled at half resolution.

Every development frame is passed through each camera pipeline of `PIPELINES` and both stripes
are measured by `cslx extract`'s default (`cslx.segmentation.extract`, method "linked"):

- ``png``: none (the rendered frame);
- ``yuyv``: YUYV 4:2:2 as a webcam streams it: BT.601 limited-range YCbCr, Cb / Cr averaged
  over horizontal pixel pairs, 8-bit, decoded by OpenCV (`COLOR_YUV2RGB_YUYV`, chroma
  repeated over the pair);
- ``jpeg420-95`` / ``-85`` / ``-70``: Pillow's JPEG encoder with 4:2:0 subsampling at quality
  95 / 85 / 70, decoded by OpenCV (libjpeg's fancy upsampling, as `cslx.images.read_rgb`);
- ``jpeg444-70``: the same at quality 70 without subsampling (the compression alone).

Frames: the robust-extraction development set (seeds 7100–7117, one seed per condition of
`experiments.robust_extraction`, frame 0 by default; metrics of its table: detection, gross
> 1 mm, median and p95 of the 3-D error in mm), and flat walls (`experiments.flat_wall`'s
rendering, saturated stripes with and without sun, development seeds 61–64, plus the same
walls lit by a saturated green laser): RMS (px) of the undistorted centres about their line.
Held-out seeds (9100–9117, 51–54) are not used.

`--variants` runs the detector with `cslx.segmentation.robust.CHROMA_REFINE` (and
`CHROMA_SATURATED` after an @, `chroma.PAIR_MARGIN` after a ~) set to other choices
(`set_variant`; A/B of the signal);
rendered frames are cached in `--cache`.

Writes `chroma_subsampling.csv` and `chroma_subsampling.md` in `--out`.
"""

from __future__ import annotations

import io
import os
import time

import numpy as np

from experiments import common as C

PIPELINES = ("png", "yuyv", "jpeg420-95", "jpeg420-85", "jpeg420-70", "jpeg444-70")
FLAT = ("saturated", "saturated_sunny", "saturated_green")
FIELDS = [
    "variant",
    "pipeline",
    "stripe",
    "detection_rate",
    "gross_rate",
    "median_mm",
    "p95_mm",
    "flat_rms_px",
    "flat_rms_max_px",
    "flat_max_px",
    "ms_per_frame",
]


def yuyv(image: np.ndarray) -> np.ndarray:
    """RGB → YUYV 4:2:2 (BT.601 limited range, chroma averaged over pixel pairs) → RGB."""
    import cv2

    x = image.astype(np.float64)
    r, g, b = x[..., 0], x[..., 1], x[..., 2]
    y = 16 + (65.481 * r + 128.553 * g + 24.966 * b) / 255
    cb = 128 + (-37.797 * r - 74.203 * g + 112.0 * b) / 255
    cr = 128 + (112.0 * r - 93.786 * g - 18.214 * b) / 255
    cb = 0.5 * (cb[:, 0::2] + cb[:, 1::2])
    cr = 0.5 * (cr[:, 0::2] + cr[:, 1::2])
    h, w = y.shape
    buf = np.empty((h, w, 2))
    buf[..., 0] = y
    buf[:, 0::2, 1] = cb
    buf[:, 1::2, 1] = cr
    buf = np.clip(np.round(buf), 0, 255).astype(np.uint8)
    return cv2.cvtColor(buf, cv2.COLOR_YUV2RGB_YUYV)


def jpeg(image: np.ndarray, quality: int, subsampling: int) -> np.ndarray:
    """RGB → JPEG (Pillow; subsampling 0: 4:4:4, 1: 4:2:2, 2: 4:2:0) → RGB (OpenCV decoder)."""
    import cv2
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(image).save(buf, format="JPEG", quality=quality, subsampling=subsampling)
    bgr = cv2.imdecode(np.frombuffer(buf.getvalue(), np.uint8), cv2.IMREAD_COLOR)
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def through(image: np.ndarray, pipeline: str) -> np.ndarray:
    """The frame as the camera pipeline `pipeline` (`PIPELINES`) delivers it."""
    if pipeline == "png":
        return image
    if pipeline == "yuyv":
        return yuyv(image)
    kind, quality = pipeline.split("-")
    return jpeg(image, int(quality), {"jpeg420": 2, "jpeg422": 1, "jpeg444": 0}[kind])


def _flat_nuisance(name: str):
    from cslx import sim
    from cslx.sim.render import LASER_RGB

    if name == "saturated_green":
        return sim.HARD_NUISANCES["saturated"]._replace(laser_rgb=LASER_RGB["green"])
    return name


def load_frames(cache: str, seed: int, frames: int, flat_seeds: tuple[int, ...], sensor):
    """[(label, image, gt or None)]: development frames and flat walls, cached as .npz."""
    from experiments.flat_wall import render_flat
    from experiments.robust_extraction import conditions

    os.makedirs(cache, exist_ok=True)
    out = []
    jobs = [
        (f"{k}-{n}-{s}-{i}", lambda k=k, n=n, s=s, i=i: C.frame_at(k, n, s, i, sensor))
        for s, (k, n) in enumerate(conditions(), start=seed)
        for i in range(frames)
    ]
    jobs += [
        (f"flat-{n}-{s}", lambda n=n, s=s: render_flat(_flat_nuisance(n), s, sensor))
        for n in FLAT
        for s in flat_seeds
    ]
    for label, render in jobs:
        path = os.path.join(cache, label + ".npz")
        if os.path.exists(path):
            z = np.load(path, allow_pickle=True)
            image, gt = z["image"], z["gt"].item()
        else:
            image, gt = render()
            gt = {k: v for k, v in gt.items() if k in ("h_xyz", "v_xyz")}
            np.savez(path, image=image, gt=np.array(gt, dtype=object))
        out.append((label, np.asarray(image), gt))
    return out


def centres(image, stripe: str):
    from cslx import segmentation as seg

    return seg.centres_to_pixels(seg.extract(image, "linked", stripe=stripe), stripe)


def evaluate(frames, pipelines, sensor, variant: str) -> list[dict]:
    """Rows of `FIELDS` for every pipeline and stripe (the detector as configured now)."""
    from experiments.flat_wall import line_residuals

    rows = []
    for pipe in pipelines:
        pools = {s: C.Pool() for s in "hv"}
        flat = {s: [] for s in "hv"}
        flat_max = {s: 0.0 for s in "hv"}
        ms = []
        for label, image, gt in frames:
            img = through(image, pipe)
            for stripe in "hv":
                t = time.perf_counter()
                uv = np.asarray(centres(img, stripe))
                ms.append(1e3 * (time.perf_counter() - t))
                if label.startswith("flat"):
                    r = line_residuals(uv, sensor.camera)
                    flat[stripe].append(float(np.sqrt(np.mean(r**2))) if len(r) else np.nan)
                    flat_max[stripe] = max(flat_max[stripe], float(np.max(np.abs(r), initial=0)))
                else:
                    truth = gt[C.STRIPE_GT[stripe]]
                    pools[stripe].add(*C.point_errors(uv, truth, sensor, C.STRIPE_PLANE[stripe]))
        for stripe in "hv":
            s = pools[stripe].summary()
            f = np.asarray(flat[stripe])
            rows.append(
                dict(
                    variant=variant,
                    pipeline=pipe,
                    stripe=stripe,
                    detection_rate=s["detection_rate"],
                    gross_rate=s["gross_rate"],
                    median_mm=s["median_mm"],
                    p95_mm=s["p95_mm"],
                    flat_rms_px=float(np.sqrt(np.mean(f**2))) if len(f) else np.nan,
                    flat_rms_max_px=float(np.max(f)) if len(f) else np.nan,
                    flat_max_px=flat_max[stripe],
                    ms_per_frame=float(np.median(ms[2:] if len(ms) > 4 else ms)),
                )
            )
            print(_line(rows[-1]), flush=True)
    return rows


def _line(r) -> str:
    return (
        f"| {r['variant']} | {r['pipeline']} | {r['stripe']} | {100 * r['detection_rate']:.2f} | "
        f"{100 * r['gross_rate']:.2f} | {r['median_mm']:.4f} | {r['p95_mm']:.3f} | "
        f"{r['flat_rms_px']:.3f} | {r['flat_rms_max_px']:.3f} | {r['flat_max_px']:.3f} | "
        f"{r['ms_per_frame']:.0f} |"
    )


def set_variant(variant: str):
    """Set `robust.CHROMA_REFINE` (and `CHROMA_SATURATED` after an @) from a variant name:
    "default" leaves them, "none" turns the chroma test off, e.g. "luma@0" uses the luma on
    every subsampled frame, "luma*0.5@0" averages its centres with the colour space's, and
    "luma*0.5~8" sets `chroma.PAIR_MARGIN` to 8 DN (0: off)."""
    from cslx.segmentation import chroma, robust

    if variant == "default":
        return
    name, _, share = variant.partition("@")
    name, _, margin = name.partition("~")
    name, _, blend = name.partition("*")
    if margin:
        chroma.PAIR_MARGIN = float(margin)
    robust.CHROMA_REFINE = None if name == "none" else name
    robust.CHROMA_BLEND = float(blend) if blend else 1.0
    if share:
        robust.CHROMA_SATURATED = float(share)


def main(
    frames: int = 1,
    seed: int = 7100,
    flat_seeds=(61, 62, 63, 64),
    pipelines=PIPELINES,
    variants=("default",),
    out: str = str(C.RESULTS),
    cache: str = "/tmp/cslx_chroma_frames",
):
    """Score every variant × pipeline × stripe; write chroma_subsampling.{csv,md}."""
    from cslx.provenance import provenance, provenance_md, write_csv
    from cslx.segmentation import chroma, robust
    from cslx.sensor import default_sensor

    sensor = default_sensor()
    load_start = C.load_average()
    t0 = time.time()
    data = load_frames(cache, seed, frames, tuple(flat_seeds), sensor)
    rows = []
    default = robust.CHROMA_REFINE, robust.CHROMA_SATURATED, robust.CHROMA_BLEND
    margin = chroma.PAIR_MARGIN
    for variant in variants:
        set_variant(variant)
        try:
            rows += evaluate(data, pipelines, sensor, variant)
        finally:
            robust.CHROMA_REFINE, robust.CHROMA_SATURATED, robust.CHROMA_BLEND = default
            chroma.PAIR_MARGIN = margin
    os.makedirs(out, exist_ok=True)
    write_csv(os.path.join(out, "chroma_subsampling.csv"), rows, FIELDS)
    prov = provenance(
        dict(frames=frames, seed=seed, flat_seeds=list(flat_seeds), variants=list(variants))
    )
    md = [
        "# Real-camera formats: the linked detector on chroma-subsampled frames",
        "",
        f"Development frames: seeds {seed}–{seed + 17} (frames 0–{frames - 1}, 18 conditions), "
        f"flat walls {', '.join(FLAT)} at seeds {', '.join(map(str, flat_seeds))}. Load "
        f"average at start {load_start}, at end {C.load_average()}; {time.time() - t0:.0f} s. "
        "ms: median wall time per frame and stripe inside the scoring loop (warm).",
        "",
        "| variant | pipeline | stripe | detection % | gross % | median mm | p95 mm | "
        "flat RMS px | worst flat RMS px | flat max px | ms |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
        *[_line(r) for r in rows],
        "",
        provenance_md(prov),
        "",
    ]
    with open(os.path.join(out, "chroma_subsampling.md"), "w", encoding="utf-8") as f:
        f.write("\n".join(md))
    return rows


if __name__ == "__main__":
    a = C.parser(__doc__, 1, 7100)
    a.add_argument("--flat-seeds", default="61,62,63,64")
    a.add_argument("--pipelines", default=",".join(PIPELINES))
    a.add_argument("--variants", default="default", help="comma-separated CHROMA_REFINE values")
    a.add_argument("--cache", default="/tmp/cslx_chroma_frames")
    args = a.parse_args()
    main(
        1 if args.quick else args.frames,
        args.seed,
        tuple(int(s) for s in args.flat_seeds.split(",")),
        tuple(args.pipelines.split(",")),
        tuple(args.variants.split(",")),
        args.out,
        args.cache,
    )
