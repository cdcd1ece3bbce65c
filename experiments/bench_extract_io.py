"""`cslx extract` on an archive: the I/O side (decoding, CSV writing) and end to end.

Three measurements, each with the machine load (os.getloadavg) recorded beside it:

1. decoding N PNG frames: one after the other (cv2.imread + RGB) versus
   `cslx.cli.extract.read_ahead` (a thread pool decoding ahead), with a stand-in compute of
   `--compute-ms` per frame so that the overlap shows;
2. writing the centre CSV of N frames (640 + 480 centres each): `csv.writer` rows of
   f"{x:.4f}" fields versus `cslx.cli.extract.format_rows` (byte-identical output);
3. end to end, `python -m cslx extract --method med` over N frames and over 8 frames, per
   frame = (T_N − T_8) / (N − 8) so that start-up and compile cancel; with
   `--baseline-tree DIR` the same for the `cslx` of another checkout (e.g. main before
   this change), interleaved, medians over `--repeats`.

Usage: python -m experiments.bench_extract_io --data DIR [--n 100] [--baseline-tree DIR]
(DIR written by `cslx render`). Prints a Markdown table; writes nothing.
"""

from __future__ import annotations

import argparse
import csv
import glob
import io
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _load() -> str:
    return "/".join(f"{x:.1f}" for x in os.getloadavg())


def bench_decode(paths, compute_ms: float) -> dict:
    import cv2

    from cslx.cli.extract import read_ahead

    def work():
        time.sleep(compute_ms / 1e3)  # releases the GIL like XLA does while computing

    t0 = time.perf_counter()
    for p in paths:
        cv2.cvtColor(cv2.imread(p, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        work()
    seq = time.perf_counter() - t0
    t0 = time.perf_counter()
    for _, rgb in read_ahead(paths):
        assert not isinstance(rgb, OSError)
        work()
    ahead = time.perf_counter() - t0
    n = len(paths)
    return {
        "sequential_ms_per_frame": 1e3 * seq / n,
        "read_ahead_ms_per_frame": 1e3 * ahead / n,
        "compute_ms": compute_ms,
        "load": _load(),
    }


def bench_csv(n_frames: int, repeats: int = 3) -> dict:
    from cslx.cli.extract import format_rows

    rng = np.random.default_rng(0)
    blocks = [
        (f"frames/frame_{i:05d}.png", s, rng.uniform(0, 640, (640 if s == "h" else 480, 2)))
        for i in range(n_frames)
        for s in ("h", "v")
    ]
    old, new = [], []
    for _ in range(repeats):
        buf = io.StringIO()
        t0 = time.perf_counter()
        w = csv.writer(buf)
        for path, s, uv in blocks:
            w.writerows([[path, s, f"{u:.4f}", f"{v:.4f}"] for u, v in uv])
        old.append(time.perf_counter() - t0)
        a = buf.getvalue()
        buf = io.StringIO()
        t0 = time.perf_counter()
        for path, s, uv in blocks:
            buf.write(format_rows(path, s, uv))
        new.append(time.perf_counter() - t0)
        assert buf.getvalue() == a
    return {
        "csv_writer_ms_per_frame": 1e3 * np.median(old) / n_frames,
        "format_rows_ms_per_frame": 1e3 * np.median(new) / n_frames,
        "load": _load(),
    }


def _run_cli(tree: str, paths, out: str) -> float:
    cmd = [sys.executable, "-m", "cslx", "extract", "--method", "med", *paths, "--out", out]
    env = dict(os.environ, PYTHONPATH=tree)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{tree}: rc {proc.returncode}: {proc.stderr[-500:]}")
    return dt


def bench_end_to_end(paths, trees: dict[str, str], repeats: int) -> dict:
    n = len(paths)
    times: dict[str, dict[int, list[float]]] = {k: {8: [], n: []} for k in trees}
    loads = []
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(repeats):
            for name, tree in trees.items():  # interleaved: the load hits both alike
                for m in (8, n):
                    loads.append(os.getloadavg()[0])
                    times[name][m].append(_run_cli(tree, paths[:m], os.path.join(tmp, "c.csv")))
    out = {}
    for name in trees:
        t8, tn = np.median(times[name][8]), np.median(times[name][n])
        out[name] = {
            "ms_per_frame": 1e3 * (tn - t8) / (n - 8),
            f"T_{n}_s": float(tn),
            "T_8_s": float(t8),
        }
    out["load_1min_min_max"] = f"{min(loads):.1f}–{max(loads):.1f}"
    return out


def main(argv=None) -> None:
    from cslx.environment import configure

    configure()
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True, help="folder of PNG frames (`cslx render`)")
    ap.add_argument("--n", type=int, default=100, help="frames (default 100)")
    ap.add_argument("--compute-ms", type=float, default=20.0, help="stand-in compute per frame")
    ap.add_argument("--baseline-tree", help="another checkout to compare end to end")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--skip-cli", action="store_true", help="only the I/O micro-benchmarks")
    args = ap.parse_args(argv)
    paths = sorted(glob.glob(os.path.join(args.data, "*.png")))[: args.n]
    if len(paths) < 16:
        sys.exit(f"need at least 16 PNG frames in {args.data}, found {len(paths)}")
    print(f"# cslx extract I/O and end to end: {len(paths)} frames of {args.data}\n")
    print(f"- cpu count {os.cpu_count()}; load at start {_load()}\n")
    dec = bench_decode(paths, args.compute_ms)
    print(
        f"- decoding + {dec['compute_ms']:.0f} ms stand-in compute: sequential "
        f"{dec['sequential_ms_per_frame']:.1f} ms/frame, read-ahead "
        f"{dec['read_ahead_ms_per_frame']:.1f} ms/frame (load {dec['load']})"
    )
    c = bench_csv(len(paths))
    print(
        f"- CSV of 1120 centres per frame: csv.writer {c['csv_writer_ms_per_frame']:.2f} "
        f"ms/frame, format_rows {c['format_rows_ms_per_frame']:.2f} ms/frame "
        f"(identical bytes; load {c['load']})"
    )
    if args.skip_cli:
        return
    trees = {"this tree": ROOT}
    if args.baseline_tree:
        trees["baseline"] = os.path.abspath(args.baseline_tree)
    e2e = bench_end_to_end(paths, trees, args.repeats)
    print("\n| tree | ms per frame, (T_N − T_8)/(N − 8) | T_N s | T_8 s |\n|---|---|---|---|")
    for name in trees:
        r = e2e[name]
        print(
            f"| {name} | {r['ms_per_frame']:.1f} | {r[f'T_{len(paths)}_s']:.1f} | "
            f"{r['T_8_s']:.1f} |"
        )
    print(f"\n1-min load during the runs: {e2e['load_1min_min_max']} (medians of {args.repeats})")


if __name__ == "__main__":
    main()
