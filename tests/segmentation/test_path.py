"""Edge-preserving path smoothing (cslx.segmentation.path)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from cslx.segmentation.path import smooth_path


def _kinked(rng, n=640, noise=0.08, corr=4):
    """A plate – bead – plate path with two sharp corners, plus correlated noise; (pos, truth)."""
    j = np.arange(n, dtype=float)
    truth = 300.0 + 0.05 * j
    bead = (j > 280) & (j < 360)
    truth = truth - np.where(bead, 6.0 - np.abs(j - 320) * 0.15, 0.0)  # corners at 280, 360
    white = rng.normal(0, 1, n + corr)
    speckle = np.convolve(white, np.ones(corr) / np.sqrt(corr), "valid")[:n]
    return (truth + noise * speckle).astype(np.float32), truth


def test_straight_parts_average_and_corners_stay_sharp():
    rng = np.random.default_rng(3)
    errs_raw, errs, corner_raw, corner = [], [], [], []
    for _ in range(8):
        pos, truth = _kinked(rng)
        valid = np.ones(len(pos), bool)
        out, factor = smooth_path(jnp.asarray(pos), jnp.asarray(valid), 0.08)
        out, factor = np.asarray(out), np.asarray(factor)
        flat = np.r_[0:250, 390:640]
        errs_raw.append(pos[flat] - truth[flat])
        errs.append(out[flat] - truth[flat])
        near = np.r_[275:286, 355:366]
        corner_raw.append(pos[near] - truth[near])
        corner.append(out[near] - truth[near])
        assert (factor <= 1.0).all() and (factor > 0).all()
        assert factor[flat].mean() < 0.5  # the plates average many centres
    rms = lambda e: float(np.sqrt(np.mean(np.concatenate(e) ** 2)))  # noqa: E731
    assert rms(errs) < 0.4 * rms(errs_raw)
    # A single ±96 window would cut the corner by ≈ 1 px; the adaptive one stays at noise level.
    assert rms(corner) < 1.5 * rms(corner_raw)


def test_gaps_and_invalid_centres_are_kept_as_they_were():
    rng = np.random.default_rng(4)
    pos, truth = _kinked(rng)
    valid = np.ones(len(pos), bool)
    valid[100:140] = False
    pos[100:140] = np.nan
    out, factor = smooth_path(jnp.asarray(np.nan_to_num(pos)), jnp.asarray(valid), 0.08)
    out = np.asarray(out)
    assert (out[100:140] == 0).all() and (np.asarray(factor)[100:140] == 1).all()
    assert np.isfinite(out[valid]).all()
    assert np.abs(out[valid] - truth[valid]).max() < 0.5


def test_path_shorter_than_the_longest_window():
    rng = np.random.default_rng(6)
    pos = (80.0 + 0.1 * np.arange(60) + rng.normal(0, 0.05, 60)).astype(np.float32)
    out, _ = smooth_path(jnp.asarray(pos), jnp.ones(60, bool), 0.05)
    assert np.isfinite(np.asarray(out)).all()
    assert np.abs(np.asarray(out) - (80.0 + 0.1 * np.arange(60))).mean() < 0.03


def test_jit_and_vmap_match_single_calls():
    rng = np.random.default_rng(5)
    paths = np.stack([_kinked(rng)[0] for _ in range(3)])
    valid = np.ones(paths.shape, bool)
    batched = jax.jit(jax.vmap(lambda p, v: smooth_path(p, v, 0.08)[0]))(paths, valid)
    single = np.stack(
        [np.asarray(smooth_path(p, v, 0.08)[0]) for p, v in zip(paths, valid, strict=True)]
    )
    # float32 rounding of values ≈ 300 px
    np.testing.assert_allclose(np.asarray(batched), single, atol=1e-3)


def test_one_sided_windows_reach_up_to_the_corners():
    # Next to a corner the symmetric window must stay short (it would straddle the corner);
    # the one-sided windows (`sided`) average the plate up to the corner from its own side.
    rng = np.random.default_rng(7)
    both, sym, flat_both, flat_sym = [], [], [], []
    near = np.r_[262:280, 281:299, 342:360, 361:379]  # within 18 centres of a corner
    flat = np.r_[40:220, 420:600]
    for _ in range(8):
        pos, truth = _kinked(rng)
        valid = jnp.ones(len(pos), bool)
        a = np.asarray(smooth_path(jnp.asarray(pos), valid, 0.08)[0]) - truth
        b = np.asarray(smooth_path(jnp.asarray(pos), valid, 0.08, sided=True)[0]) - truth
        sym.append(a[near])
        both.append(b[near])
        flat_sym.append(a[flat])
        flat_both.append(b[flat])
    rms = lambda e: float(np.sqrt(np.mean(np.concatenate(e) ** 2)))  # noqa: E731
    assert rms(both) < 0.9 * rms(sym)  # 0.80 at this seed
    assert rms(flat_both) < 1.1 * rms(flat_sym)  # 1.03


def test_unit_weights_are_the_unweighted_fit():
    rng = np.random.default_rng(4)
    pos, _ = _kinked(rng)
    valid = np.ones(len(pos), bool)
    valid[100:110] = False
    args = (jnp.asarray(pos), jnp.asarray(valid), 0.08)
    plain, f0 = smooth_path(*args, sided=True)
    ones, f1 = smooth_path(*args, sided=True, weights=jnp.ones(len(pos)))
    np.testing.assert_allclose(np.asarray(ones), np.asarray(plain), atol=1e-4)
    np.testing.assert_allclose(np.asarray(f1), np.asarray(f0), rtol=1e-4)


def test_weights_keep_a_noisy_stretch_out_of_its_quiet_neighbours():
    """A stretch whose centres scatter 8× more (a glint's edge, a dark patch): with weights
    ≈ its relative precision^½ (1/8) the fits of the quiet centres next to it lean on
    their own side (RMS 0.018 → 0.007 px), and the stretch itself is no worse."""
    n = 640
    j = np.arange(n)
    noisy = (j >= 250) & (j < 330)
    near = np.r_[200:250, 330:380]
    err = {"plain": [], "weighted": []}
    for seed in range(6):
        rng = np.random.default_rng(10 + seed)
        truth = 300.0 + 0.05 * j
        pos = truth + np.where(noisy, 0.4, 0.05) * rng.normal(size=n)
        args = (jnp.asarray(pos, jnp.float32), jnp.ones(n, bool), 0.1)
        w = jnp.asarray(np.where(noisy, 1 / 8.0, 1.0), jnp.float32)
        err["plain"].append(np.asarray(smooth_path(*args, sided=True)[0]) - truth)
        err["weighted"].append(np.asarray(smooth_path(*args, sided=True, weights=w)[0]) - truth)
    rms = {
        k: lambda sl, v=v: float(np.sqrt(np.mean(np.stack(v)[:, sl] ** 2))) for k, v in err.items()
    }
    assert rms["weighted"](near) < 0.5 * rms["plain"](near)
    assert rms["weighted"](noisy) < 1.05 * rms["plain"](noisy)


def test_local_lines_take_the_curvature_of_a_long_window():
    """Local lines (`lines`) through the centres less k m², k = κ/2 of the ±`CURVATURE_HALF`
    quadratic: on a parabola (the vertical stripe off the image centre, bent by the lens
    distortion: second difference 0.065 px at lag 24) they are exact, where plain lines
    (`curvature_half=0`) are biased by up to the ICI's tolerance; on a straight noisy path
    they average more centres than the quadratics for the same variance (module docstring,
    "Local lines")."""
    n = 480
    j = np.arange(n, dtype=float)
    kw = dict(sided=True, halves=(2, 4, 8, 16, 32, 64, 96, 128, 192, 256), correlation=6.0)
    truth = 300.0 + 0.05 * j + 0.065 / 24**2 / 2 * (j - 240.0) ** 2
    args = (jnp.asarray(truth, jnp.float32), jnp.ones(n, bool), 0.03)
    err = {
        k: np.abs(np.asarray(smooth_path(*args, lines=True, curvature_half=h, **kw)[0]) - truth)
        for k, h in (("lines", 512), ("plain lines", 0))
    }
    assert err["lines"].max() < 2e-3  # 3e-4 (float32)
    assert err["plain lines"].max() > 0.02  # 0.039
    straight = {"quadratics": [], "lines": []}
    for seed in range(6):
        rng = np.random.default_rng(30 + seed)
        line = 300.0 + 0.05 * j
        pos = line + 0.03 * np.convolve(rng.normal(size=n + 3), np.ones(4) / 2, "valid")
        args = (jnp.asarray(pos, jnp.float32), jnp.ones(n, bool), 0.03)
        straight["quadratics"].append(np.asarray(smooth_path(*args, **kw)[0]) - line)
        straight["lines"].append(np.asarray(smooth_path(*args, lines=True, **kw)[0]) - line)
    rms = {k: float(np.sqrt(np.mean(np.square(v)))) for k, v in straight.items()}
    assert rms["lines"] < 0.95 * rms["quadratics"]  # 0.0046 against 0.0052 px
