"""Extract laser stripe centres from images into a centre CSV.

Writes one row per centre with header `image,stripe,u,v` (plus `x,y,z` in mm, camera frame,
when --calib is given): stripe `h` has at most one centre per image column, stripe `v` at
most one per image row; pixel coordinates are OpenCV's (origin at the centre of the top-left
pixel). Arguments are checked before any work: a missing image, a directory given as an
image, a bad --sigma or an unwritable --out is a usage error (exit 2). Unreadable images,
images of another size than the calibration and frames without a stripe are reported on
stderr; the other images are still processed, and the exit status is 1 if any image failed.
The CSV is written atomically (`cslx.files`): it appears complete or not at all, and a run
in which every image failed leaves no file (a previous one stays as it was). On success one
summary line gives the images, the centres per stripe and the colour weights used (the ones
`--space auto` chose).

Images are read by `cslx.images.read_rgb`: any format OpenCV decodes, grayscale files as three
equal channels, alpha dropped, 16-bit scaled to 8 bits, EXIF orientation applied; a truncated
PNG or JPEG is reported and skipped (OpenCV would decode half a JPEG). A grayscale image (a
monochrome camera) gets `GRAY_WEIGHTS` instead of fixed colour weights such as R − G, which are
zero on it; the default method's `--space auto` finds the stripe in it by itself.

The default method "linked" (issue 11: candidate ridges linked along the stripe, clipped cores,
width-aware σ; evidence in results/robust_extraction.md) adds the optional columns `sigma_px`
(predicted standard deviation of the centre along the search axis, px) and `saturated` (1: the
centre of a clipped core, taken from the plateau's flanks); a stripe it does not find (e.g. the
laser off: `cslx.segmentation.presence`) gets one line "no stripe found in FILE (horizontal):
…". The paper's MED + Steger is `--method med` (Table 6). With fixed colour weights (every
--space but auto) it runs MED only where the stripe is (`cslx.segmentation.med_bands`, issue
13): a band around each stripe from a first pass, linear-phase MED in the band warm-started from
the previous image's band filter, Steger there; an image whose stripe does not fit a band gets
the paper's full-frame MED. Images are processed in batches of `MED_BATCH`; the CSV rows of one
batch are written while the next batch computes. Centres agree with full-frame MED within a few
hundredths of a pixel (results/bench_speed.md); with --space auto every image goes through
full-frame MED.

Images are decoded in a thread pool ahead of the compute (OpenCV releases the GIL), and the
rows of each image are formatted in one call, so that reading and writing overlap the
segmentation instead of adding to it.

With more than one JAX device (GPUs, several hosts, or CPU devices forced with
XLA_FLAGS=--xla_force_host_platform_device_count=N), the JAX methods (steger, med) with fixed
colour weights process the images in batches sharded over all devices
(`cslx.segmentation.shard`).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

NAME = "extract"
HELP = "stripe centres of images → centre CSV (CM, LA, QA, AA, Steger, MED + Steger)"

METHODS = ("cm", "la", "qa", "aa", "steger", "med", "linked")
#: Default method: the linked detector (`cslx.segmentation.robust`, issue 11).
DEFAULT_METHOD = "linked"
#: Images decoded ahead of the one being segmented, and the decoding threads.
READ_AHEAD = 8
READ_THREADS = 1  # one decoder keeps ahead of the compute; more compete with XLA on 2 cores
#: Images per compiled call of the band MED path (`--method med` with fixed colour weights).
MED_BATCH = 8
#: Colour weights for a grayscale image (a monochrome camera's frame, R = G = B): its gray
#: values themselves. Fixed weights that sum to zero, like the default R − G of the paper's
#: methods, would turn it into a black image; the linked method's kurtosis search (`auto`)
#: already finds the stripe in one and keeps its own weights.
GRAY_WEIGHTS = (1.0, 0.0, 0.0)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("images", nargs="+", metavar="IMAGE", help="image files (PNG, JPEG, …)")
    parser.add_argument(
        "--method",
        choices=METHODS,
        default=DEFAULT_METHOD,
        help=f"segmentation method (default: {DEFAULT_METHOD}; the paper's: med)",
    )
    parser.add_argument(
        "--space",
        default=None,
        help="colour space: r, r-g, gray, auto (kurtosis search) or W_R,W_G,W_B "
        "(default: auto for linked, r-g for the others)",
    )
    parser.add_argument(
        "--stripe",
        choices=("h", "v", "both"),
        default="both",
        help="horizontal (h), vertical (v) or both stripes of the cross (default both)",
    )
    parser.add_argument(
        "--sigma",
        type=float,
        default=None,
        help="Steger's Gaussian scale in pixels, > 0 (default 2 for steger and med; linked: "
        "from the measured stripe width)",
    )
    parser.add_argument("--calib", metavar="FILE", help="calibration JSON: adds x,y,z in mm")
    parser.add_argument("--out", metavar="FILE.csv", required=True, help="centre CSV to write")


def _usage_error(msg: str) -> int:
    print(f"cslx extract: {msg}", file=sys.stderr)
    return 2


def _read_rgb(path: str):
    """8-bit RGB pixels (`cslx.images.read_rgb`: gray, alpha, 16-bit, EXIF, truncated files)."""
    from ..images import read_rgb

    return read_rgb(path)


def read_ahead(paths, ahead: int = READ_AHEAD, threads: int = READ_THREADS):
    """Yield (path, RGB image or the OSError) in order, decoding up to `ahead` in threads."""
    from collections import deque
    from concurrent.futures import ThreadPoolExecutor

    def read(path):
        try:
            return _read_rgb(path)
        except OSError as err:
            return err

    with ThreadPoolExecutor(max_workers=threads, thread_name_prefix="cslx-read") as pool:
        queue: deque = deque()
        it = iter(paths)
        for path in it:
            queue.append((path, pool.submit(read, path)))
            if len(queue) >= ahead:
                break
        while queue:
            path, fut = queue.popleft()
            nxt = next(it, None)
            if nxt is not None:
                queue.append((nxt, pool.submit(read, nxt)))
            yield path, fut.result()


def _csv_field(text: str) -> str:
    """`text` as one CSV field (quoted when it holds a comma, quote or line break)."""
    if any(c in text for c in ',"\r\n'):
        return '"' + text.replace('"', '""') + '"'
    return text


def format_rows(path: str, stripe: str, uv, xyz=None, extra=None) -> str:
    """The CSV rows of one image's centres, `image,stripe,u,v[,x,y,z]`, in one string.

    Equal, byte for byte, to `csv.writer` rows of `f"{value:.4f}"` fields (lines end in
    CRLF like `csv.writer`'s), but formatted with one `%` call for the whole block.
    """
    import numpy as np

    uv = np.asarray(uv, float)
    if len(uv) == 0:
        return ""
    cols = [uv] if xyz is None else [uv, np.asarray(xyz, float)]
    values = np.concatenate(cols, axis=1)
    prefix = f"{_csv_field(path)},{stripe},".replace("%", "%%")
    fields = ["%.4f"] * values.shape[1]
    if extra is not None:  # linked: sigma_px (%.4f) and saturated (0/1)
        values = np.concatenate([values, np.asarray(extra, float)], axis=1)
        fields += ["%.4f", "%d"]
    line = prefix + ",".join(fields) + "\r\n"
    return (line * len(values)) % tuple(values.ravel().tolist())


def run(args: argparse.Namespace) -> int:
    from ..files import output_problem

    # ---- arguments, before any work (and before JAX loads)
    if args.sigma is not None and not (math.isfinite(args.sigma) and args.sigma > 0):
        return _usage_error(
            f"--sigma {args.sigma}: must be a positive number of pixels (Steger's scale, e.g. 2)"
        )
    from ..images import paths_problem

    problem = paths_problem(args.images)
    if problem:
        return _usage_error(problem)
    why = output_problem(args.out)
    if why:
        return _usage_error(f"--out {args.out}: {why}")
    out_real = os.path.realpath(args.out)
    if any(os.path.realpath(p) == out_real for p in args.images):
        return _usage_error(f"--out {args.out}: is one of the input images; choose another name")
    from ..segmentation.colour import parse_space

    if args.space is None:
        args.space = "auto" if args.method == "linked" else "r-g"
    try:
        space = parse_space(args.space)
    except ValueError as err:
        return _usage_error(str(err))
    stripes = ("h", "v") if args.stripe == "both" else (args.stripe,)
    sensor = None
    if args.calib:
        from ..sensor import CalibrationError, load_sensor

        try:
            sensor = load_sensor(args.calib)
        except (OSError, CalibrationError) as err:
            return _usage_error(f"--calib: {err}")  # the message names the file
        if any(not sensor.has_plane(s) for s in stripes):
            # A one-plane (line-laser) calibration triangulates its own stripe only.
            have = sensor.plane_stripes
            if args.stripe != "both":
                try:
                    sensor.plane_index(args.stripe)
                except CalibrationError as err:
                    return _usage_error(f"--stripe {args.stripe} with {args.calib}: {err}")
            stripes = tuple(s for s in stripes if s in have)
            print(
                f"cslx extract: {args.calib} holds one laser plane ({have[0]} stripe): "
                "extracting that stripe only",
                file=sys.stderr,
            )
    return _extract(args, space, stripes, sensor)


class _NothingWritten(Exception):
    """Every image failed: abandon the atomic output so that no file appears."""


def _extract(args, space, stripes, sensor) -> int:
    import numpy as np
    from tqdm import tqdm

    from ..files import atomic_write
    from ..segmentation import DEFAULT_SIGMA

    linked = args.method == "linked"
    sigma = args.sigma if args.sigma is not None or linked else DEFAULT_SIGMA
    header = ["image", "stripe", "u", "v"] + (["x", "y", "z"] if sensor is not None else [])
    header += ["sigma_px", "saturated"] if linked else []
    stats = _Stats(stripes)
    t0 = time.perf_counter()
    batched = _sharded_path(args)
    gray_weights = not (linked and space == "auto")  # fixed weights: gray frames need others
    bands = _band_path(args, stripes, sigma) if batched is None else None
    try:
        with atomic_write(args.out, "w", newline="") as out:
            out.write(",".join(header) + "\r\n")
            images = tqdm(
                read_ahead(args.images),
                total=len(args.images),
                unit="img",
                disable=len(args.images) < 10,
                file=sys.stderr,
                leave=False,
            )
            for path, rgb in images:
                if isinstance(rgb, OSError):
                    stats.fail(path, f"{rgb}; skipped")
                    continue
                h, w = rgb.shape[:2]
                if sensor is not None and tuple(sensor.camera.image_size) != (w, h):
                    cw, ch = sensor.camera.image_size
                    stats.fail(
                        path, f"image is {w}×{h} but the calibration is for {cw}×{ch}; skipped"
                    )
                    continue
                if gray_weights and is_gray(rgb):
                    stats.gray += 1
                    if batched:  # the rows stay in input order
                        _flush(batched, stripes, args, sigma, sensor, out, stats)
                    if bands is not None:
                        bands.finish(sensor, out, stats)
                    _one_image(path, rgb, stripes, args.method, GRAY_WEIGHTS, sigma, sensor, out,
                               stats, record=False)  # fmt: skip
                    continue
                if batched is not None:
                    batched.append((path, rgb))
                    if len(batched) >= _BATCH_PER_DEVICE * batched.n_devices:
                        _flush(batched, stripes, args, sigma, sensor, out, stats)
                    continue
                if bands is not None:
                    bands.add(path, rgb, sensor, out, stats)
                    continue
                _one_image(path, rgb, stripes, args.method, space, sigma, sensor, out, stats)
            if batched:
                _flush(batched, stripes, args, sigma, sensor, out, stats)
            if bands is not None:
                bands.finish(sensor, out, stats)
            if stats.ok == 0:
                raise _NothingWritten
    except _NothingWritten:
        print(
            f"cslx extract: none of the {len(args.images)} images gave a stripe; "
            f"{args.out} not written",
            file=sys.stderr,
        )
        return 1
    except OSError as err:
        print(f"cslx extract: cannot write {args.out}: {err}", file=sys.stderr)
        return 1
    dt = time.perf_counter() - t0
    n = len(args.images)
    per = ", ".join(
        f"{s} {np.median(stats.centres[s]) if stats.centres[s] else 0:.0f}" for s in stripes
    )
    print(
        f"cslx extract: {stats.ok} of {n} images → {args.out}; centres per image (median) "
        f"{per}; colour weights {stats.weights_text(args.space)}; "
        f"{dt:.1f} s ({1e3 * dt / n:.1f} ms/image)",
        file=sys.stderr,
    )
    if stats.gray:
        print(
            f"cslx extract: {stats.gray} of {n} images are grayscale (R = G = B): their gray "
            "values were used, since colour weights cannot separate a stripe in them",
            file=sys.stderr,
        )
    if stats.failed:
        print(f"cslx extract: {stats.failed} of {n} images failed", file=sys.stderr)
    return 1 if stats.failed else 0


class _Stats:
    """What the run produced: images with centres, failures, centres and weights per stripe."""

    def __init__(self, stripes):
        self.ok = 0
        self.failed = 0
        self.gray = 0  # grayscale images given GRAY_WEIGHTS
        self.centres = {s: [] for s in stripes}
        self.weights = {s: [] for s in stripes}

    def fail(self, path: str, why: str) -> None:
        print(f"cslx extract: {path}: {why}", file=sys.stderr)
        self.failed += 1

    def weights_text(self, space: str) -> str:
        import numpy as np

        parts = []
        for s, ws in self.weights.items():
            if ws:
                w = np.median(np.asarray(ws, float), axis=0)
                parts.append(f"{s} ({w[0]:.3f}, {w[1]:.3f}, {w[2]:.3f})")
        text = ", ".join(parts) if parts else "none"
        if space.strip().lower() == "auto":
            return f"chosen by auto (median over images): {text}"
        return f"{space}: {text}"


def is_gray(rgb) -> bool:
    """Whether an (H, W, 3) frame is grayscale (R = G = B everywhere: a monochrome camera's
    file, decoded to three equal channels). A sparse sample first, so a colour frame costs
    microseconds."""
    import numpy as np

    s = rgb[::16, ::16]
    if not (np.array_equal(s[..., 0], s[..., 1]) and np.array_equal(s[..., 1], s[..., 2])):
        return False
    return bool(
        np.array_equal(rgb[..., 0], rgb[..., 1]) and np.array_equal(rgb[..., 1], rgb[..., 2])
    )


def _one_image(path, rgb, stripes, method, space, sigma, sensor, out, stats, record=True) -> None:
    import numpy as np

    from ..segmentation import centres_to_pixels, extract
    from ..segmentation.interface import monochrome_for

    found = 0
    for stripe in stripes:
        kw = {} if method in ("cm", "la", "qa", "aa") else {"sigma": sigma}
        try:
            if method == "linked":  # needs the RGB frame (clipped pixels)
                from ..segmentation.orient import stripe_angle
                from ..segmentation.robust import search_space_unclipped

                weights = space
                if space == "auto":
                    weights = search_space_unclipped(rgb, 0 if stripe == "h" else 1)
                if sensor is not None and sensor.planes.shape[0] == 2:  # which is which
                    kw["stripe_deg"] = stripe_angle(sensor, stripe)
                centres = extract(rgb, method, space=weights, stripe=stripe, **kw)
            else:
                mono, weights = monochrome_for(rgb, space, stripe)
                centres = extract(mono, method, stripe=stripe, **kw)
        except Exception as err:  # one bad frame must not lose the others
            print(f"cslx extract: {path}: stripe {stripe}: {err}", file=sys.stderr)
            continue
        if record:
            stats.weights[stripe].append(np.asarray(weights, float))
        uv = centres_to_pixels(centres, stripe)
        ok = np.all(np.isfinite(uv), axis=1)
        uv = uv[ok]
        extra = None
        if centres.sigma is not None and method == "linked":
            extra = np.stack([np.asarray(centres.sigma), np.asarray(centres.saturated)], 1)[ok]
        stats.centres[stripe].append(len(uv))
        found += len(uv)
        if method == "linked" and len(uv) == 0:
            print(f"cslx extract: {no_stripe_line(path, stripe)}", file=sys.stderr)
        _write_block(out, path, stripe, uv, sensor, extra)
    if found == 0 and method == "linked":
        stats.failed += 1  # each stripe said why above
    elif found == 0:
        stats.fail(path, "no stripe found")
    else:
        stats.ok += 1


def no_stripe_line(path, stripe: str) -> str:
    """The line `cslx extract` prints for a stripe the linked detector did not find."""
    from ..segmentation import presence

    name = {"h": "horizontal", "v": "vertical"}[stripe]
    return f"no stripe found in {path} ({name}): {presence.criteria()} (laser off? out of view?)"


def _write_block(out, path, stripe, uv, sensor, extra=None) -> None:
    import numpy as np

    if len(uv) == 0:
        return
    xyz = None
    if sensor is not None:
        from ..sensor import triangulate

        xyz = np.asarray(triangulate(sensor, uv, 0 if stripe == "h" else 1))
    out.write(format_rows(path, stripe, uv, xyz, extra))


# ------------------------------------------- several devices (cslx.segmentation.shard)
_BATCH_PER_DEVICE = 16


class _Pending(list):
    """Images read but not yet processed by the sharded path: [(path, rgb)], in input order."""

    n_devices = 1


def _sharded_path(args: argparse.Namespace) -> _Pending | None:
    """A pending list when the frames should be sharded over several devices, else None.

    Used for the JAX methods (steger, med) with fixed colour weights when JAX sees more than
    one device (GPUs, several hosts after `jax.distributed`, or forced CPU devices).
    """
    from ..segmentation.colour import parse_space
    from ..segmentation.shard import JAX_METHODS, initialize_distributed

    if args.method not in JAX_METHODS or parse_space(args.space) == "auto":
        return None
    import jax

    initialize_distributed()
    if jax.device_count() < 2:
        return None
    pending = _Pending()
    pending.n_devices = jax.device_count()
    from ..segmentation.shard import device_summary

    print(f"cslx extract: frames sharded over {device_summary()}", file=sys.stderr)
    return pending


def _flush(pending: _Pending, stripes, args, sigma, sensor, out, stats) -> None:
    """Centres of the pending images (`cslx.segmentation.shard.extract_batch`), in input order."""
    import numpy as np

    from ..segmentation import centres_to_pixels
    from ..segmentation.colour import parse_space
    from ..segmentation.shard import extract_batch
    from ..segmentation.steger import Centres

    weights = np.asarray(parse_space(args.space), float)
    blocks: dict[int, list] = {i: [] for i in range(len(pending))}
    by_shape: dict[tuple, list[int]] = {}
    for i, (_, rgb) in enumerate(pending):
        by_shape.setdefault(rgb.shape, []).append(i)
    for idx in by_shape.values():
        frames = np.stack([pending[i][1] for i in idx])
        for stripe in stripes:
            try:
                c = extract_batch(frames, args.method, space=args.space, stripe=stripe, sigma=sigma)
            except Exception as err:  # one bad batch must not lose the others
                print(
                    f"cslx extract: batch of {len(idx)} images: stripe {stripe}: {err}",
                    file=sys.stderr,
                )
                continue
            for k, i in enumerate(idx):
                uv = centres_to_pixels(Centres(c.pos[k], c.valid[k], c.strength[k]), stripe)
                uv = uv[np.all(np.isfinite(uv), axis=1)]
                stats.centres[stripe].append(len(uv))
                stats.weights[stripe].append(weights)
                blocks[i].append((stripe, uv))
    for i, (path, _) in enumerate(pending):
        if any(len(uv) for _, uv in blocks[i]):
            for stripe, uv in blocks[i]:
                _write_block(out, path, stripe, uv, sensor)
            stats.ok += 1
        else:
            stats.fail(path, "no stripe found")
    pending.clear()


# ------------------------------------------- band MED (cslx.segmentation.med_bands)
def _band_path(args: argparse.Namespace, stripes, sigma) -> _BandRun | None:
    """A band-MED runner for `--method med` with fixed colour weights, else None."""
    from ..segmentation.colour import parse_space

    if args.method != "med":
        return None
    weights = parse_space(args.space)
    if isinstance(weights, str):  # "auto": per-image weights, full-frame MED
        return None
    return _BandRun(weights, stripes, sigma, min(MED_BATCH, len(args.images)))


class _BandRun:
    """Batches of images through `med_bands.extract_frames`, one batch computing while the
    previous one is written (JAX dispatches asynchronously; `np.asarray` waits)."""

    def __init__(self, weights, stripes, sigma, batch):
        from ..segmentation import med_bands

        self.weights = tuple(float(w) for w in weights)
        self.cfg = med_bands.BandConfig(weights=self.weights, sigma=float(sigma))
        self.stripes = tuple(stripes)
        self.batch = max(1, batch)
        self.pending: list = []
        self.inflight = None
        self.filters: dict = {}  # band filters per image shape, carried from batch to batch

    def add(self, path, rgb, sensor, out, stats) -> None:
        if self.pending and self.pending[0][1].shape != rgb.shape:
            self._dispatch(sensor, out, stats)
        self.pending.append((path, rgb))
        if len(self.pending) >= self.batch:
            self._dispatch(sensor, out, stats)

    def finish(self, sensor, out, stats) -> None:
        if self.pending:
            self._dispatch(sensor, out, stats)
        self._write(sensor, out, stats)

    def _dispatch(self, sensor, out, stats) -> None:
        import numpy as np

        from ..segmentation import med_bands

        items, self.pending = self.pending, []
        frames = np.stack([rgb for _, rgb in items])
        if len(items) < self.batch:  # pad: one compiled program per image shape
            pad = np.repeat(frames[-1:], self.batch - len(items), axis=0)
            frames = np.concatenate([frames, pad])
        key = frames.shape[1:]
        filters = self.filters.get(key)
        if filters is None:
            filters = med_bands.initial_filters(self.cfg)
        try:
            filters, results = med_bands.extract_frames(frames, filters, self.cfg, self.stripes)
        except Exception as err:  # one bad batch must not lose the others
            for path, _ in items:
                stats.fail(path, f"band MED: {err}")
            return
        self.filters[key] = filters
        self._write(sensor, out, stats)  # the previous batch, while this one computes
        self.inflight = (items, results)

    def _write(self, sensor, out, stats) -> None:
        import numpy as np

        from ..segmentation import centres_to_pixels

        if self.inflight is None:
            return
        items, results = self.inflight
        self.inflight = None
        arrays = [(np.asarray(r.centres.pos), np.asarray(r.centres.valid)) for r in results]
        weights = np.asarray(self.weights)
        for k, (path, _) in enumerate(items):
            found = 0
            for stripe, (pos, valid) in zip(self.stripes, arrays, strict=True):
                uv = centres_to_pixels(_PosValid(pos[k], valid[k]), stripe)
                uv = uv[np.all(np.isfinite(uv), axis=1)]
                stats.weights[stripe].append(weights)
                stats.centres[stripe].append(len(uv))
                found += len(uv)
                _write_block(out, path, stripe, uv, sensor)
            if found == 0:
                stats.fail(path, "no stripe found")
            else:
                stats.ok += 1


class _PosValid:
    """The two fields of `Centres` that `centres_to_pixels` reads."""

    def __init__(self, pos, valid):
        self.pos, self.valid = pos, valid
