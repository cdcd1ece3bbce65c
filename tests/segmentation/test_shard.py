"""Sharded archive processing (`cslx.segmentation.shard`) equals the single-device results.

The multi-device runs use 4 CPU devices forced with
``XLA_FLAGS=--xla_force_host_platform_device_count=4`` in a subprocess (the flag must be set
before JAX starts, and this test process has already started it). The reference is a second
subprocess with one device, and a plain per-frame loop over `cslx.segmentation.interface`.
"""

from __future__ import annotations

import os
import pathlib
import subprocess
import sys
import textwrap

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]

# Seven small frames (not a multiple of 4: the padding path runs), a Gaussian stripe per
# frame at a different row and slope in red, on green-tinted noise. float32 (the speed path).
_WORKER = textwrap.dedent(
    """
    import sys, json
    import numpy as np
    import jax
    from cslx.segmentation import shard
    from cslx.segmentation import extract

    def frames(n=7, h=48, w=64):
        rng = np.random.default_rng(3)
        v = np.arange(h)[:, None]
        u = np.arange(w)[None, :]
        out = []
        for i in range(n):
            centre = 12 + 3.3 * i + 0.05 * (i - 3) * u
            stripe = 200 * np.exp(-0.5 * ((v - centre) / 2.0) ** 2)
            rgb = np.stack([stripe + 30, 0.2 * stripe + 30, 25 + 0 * stripe], -1)
            rgb = rgb + rng.normal(0, 4, rgb.shape)
            out.append(np.clip(np.round(rgb), 0, 255).astype(np.uint8))
        return np.stack(out)

    out_path = sys.argv[1]
    F = frames()
    res = {}
    for method in ("steger", "med"):
        c = shard.extract_batch(F, method, stripe="h", batch_size=4)
        res[method + "_pos"] = c.pos
        res[method + "_valid"] = c.valid
    mesh = shard.frame_mesh()
    placed = shard.place_frames(F[:4], mesh)
    fn = lambda f: extract(f, "steger", stripe="h").pos
    y = shard._compiled(fn, mesh, 1)(placed)
    yv = shard._compiled(fn, mesh, None)(placed)  # plain vmap per device
    assert np.allclose(np.asarray(y), np.asarray(yv), atol=1e-4, equal_nan=True)
    info = dict(
        n_devices=jax.device_count(),
        input_devices=len(placed.sharding.device_set),
        input_shard_frames=[s.data.shape[0] for s in placed.addressable_shards],
        output_devices=len(y.sharding.device_set),
    )
    if "--loop" in sys.argv:
        for method in ("steger", "med"):
            cs = [extract(f, method, stripe="h") for f in F]
            res[method + "_loop_pos"] = np.stack([np.asarray(c.pos) for c in cs])
            res[method + "_loop_valid"] = np.stack([np.asarray(c.valid) for c in cs])
    np.savez(out_path, **res)
    print(json.dumps(info))
    """
)


def _run(tmp_path, n_devices: int, *extra: str) -> tuple[dict, dict]:
    import json

    env = dict(os.environ)
    env["OPENBLAS_NUM_THREADS"] = "1"
    env["JAX_PLATFORMS"] = "cpu"
    flags = env.get("XLA_FLAGS", "").replace("--xla_force_host_platform_device_count", "--_x")
    env["XLA_FLAGS"] = f"{flags} --xla_force_host_platform_device_count={n_devices}".strip()
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    out = tmp_path / f"out{n_devices}.npz"
    script = tmp_path / "worker.py"
    script.write_text(_WORKER)
    proc = subprocess.run(
        [sys.executable, str(script), str(out), *extra],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    info = json.loads(proc.stdout.strip().splitlines()[-1])
    with np.load(out) as z:
        return info, {k: z[k] for k in z.files}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("shard")
    return _run(tmp, 4), _run(tmp, 1, "--loop")


def test_frames_are_sharded_over_four_devices(runs):
    (info4, _), (info1, _) = runs
    assert info4["n_devices"] == 4
    assert info4["input_devices"] == 4 and info4["output_devices"] == 4
    assert info4["input_shard_frames"] == [1, 1, 1, 1]  # 4 frames, one per device
    assert info1["n_devices"] == 1 and info1["input_devices"] == 1


@pytest.mark.parametrize("method", ["steger", "med"])
def test_four_devices_equal_one_device(runs, method):
    (_, r4), (_, r1) = runs
    np.testing.assert_array_equal(r4[method + "_valid"], r1[method + "_valid"])
    assert r4[method + "_valid"].mean() > 0.8  # the stripe is found: not a vacuous comparison
    ok = r1[method + "_valid"]
    # Same compiled program per frame; only the device placement differs. float32: allow a
    # few ulp of reordering in XLA's per-device code.
    np.testing.assert_allclose(r4[method + "_pos"][ok], r1[method + "_pos"][ok], atol=1e-4)


@pytest.mark.parametrize("method", ["steger", "med"])
def test_batched_equals_per_frame_extract(runs, method):
    _, (_, r1) = runs
    valid, loop_valid = r1[method + "_valid"], r1[method + "_loop_valid"]
    assert np.mean(valid == loop_valid) > 0.99
    both = valid & loop_valid
    # vmap reorders float32 reductions (FFT sums, kurtosis weights): sub-millipixel changes.
    np.testing.assert_allclose(r1[method + "_pos"][both], r1[method + "_loop_pos"][both], atol=2e-3)


def test_bad_input_is_rejected():
    from cslx.segmentation import shard

    with pytest.raises(ValueError, match="non-empty"):
        shard.process_archive(np.zeros((0, 4, 4, 3), np.uint8), lambda f: f)
    with pytest.raises(ValueError, match="JAX methods"):
        shard.extract_batch(np.zeros((2, 8, 8, 3), np.uint8), "cm")
    with pytest.raises(ValueError, match="auto"):
        shard.extract_batch(np.zeros((2, 8, 8, 3), np.uint8), "med", space="auto")
    with pytest.raises(ValueError, match=r"\(F, H, W, 3\)"):
        shard.extract_batch(np.zeros((8, 8, 3), np.uint8), "med")


def test_extract_cli_on_four_devices_writes_the_single_device_csv(tmp_path):
    """`cslx extract` takes the sharded path with 4 devices; its CSV equals the 1-device one."""
    import csv

    import cv2

    rng = np.random.default_rng(5)
    v = np.arange(40)[:, None] + 0 * np.arange(56)[None, :]
    paths = []
    for i in range(5):
        stripe = 180 * np.exp(-0.5 * ((v - 10 - 4 * i) / 2.0) ** 2)
        rgb = np.stack([stripe + 40, 0.2 * stripe + 35, 30 + 0 * stripe], -1)
        rgb = np.clip(np.round(rgb + rng.normal(0, 3, rgb.shape)), 0, 255).astype(np.uint8)
        path = tmp_path / f"f{i}.png"
        cv2.imwrite(str(path), rgb[..., ::-1])
        paths.append(str(path))

    def run(n_devices):
        env = dict(os.environ, OPENBLAS_NUM_THREADS="1", JAX_PLATFORMS="cpu")
        env["XLA_FLAGS"] = f"--xla_force_host_platform_device_count={n_devices}"
        env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
        out = tmp_path / f"c{n_devices}.csv"
        cmd = [sys.executable, "-m", "cslx", "extract", *paths, "--method", "steger"]
        cmd += ["--stripe", "h", "--out", str(out)]
        proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=600)
        assert proc.returncode == 0, proc.stderr[-3000:]
        assert ("sharded over 4 device(s)" in proc.stderr) == (n_devices == 4)
        with open(out, newline="") as f:
            return list(csv.reader(f))

    one, four = run(1), run(4)
    assert one[0] == four[0] == ["image", "stripe", "u", "v"]
    assert len(one) == len(four) > 5 * 50  # every column of every image has a centre
    assert [r[:3] for r in one] == [r[:3] for r in four]
    v1 = np.array([float(r[3]) for r in one[1:]])
    v4 = np.array([float(r[3]) for r in four[1:]])
    np.testing.assert_allclose(v4, v1, atol=2e-3)  # vmapped float32 vs per-frame float32
