"""MED (section 3.2, eqs. (18)–(26), docs/corrections.md, 5–7) against independent references.

References: a plain NumPy loop of eqs. (22)–(24), `jax.grad` of the directly convolved
objective of eq. (19) for stationarity, and stripes rendered at known sub-pixel rows for the
delay compensation. float64 throughout (conftest) unless a test says otherwise.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.ndimage import gaussian_filter1d

from cslx.segmentation import med_fft
from cslx.segmentation.med import (
    initial_filter,
    med,
    med_apply,
    med_objective,
    med_prepare,
    med_update,
)


def stripe_image(
    h, w, centre, *, sigma=1.8, amp=100.0, bg=20.0, ramp=0.5, noise=0.5, speckle=0.0, seed=0
):
    """Gaussian stripe whose centre in column j is centre[j] (rows), plus background and noise."""
    rng = np.random.default_rng(seed)
    rows = np.arange(h)[:, None]
    stripe = amp * np.exp(-0.5 * ((rows - np.asarray(centre)[None, :]) / sigma) ** 2)
    stripe = stripe * (1 + speckle * rng.standard_normal((h, w)))
    light = bg * (1 + ramp * np.cos(np.pi * rows / h))  # uneven sunlight: no constant level
    return stripe + light + noise * rng.standard_normal((h, w))


def wavy_centre(h, w, phase=0.0):
    cols = np.arange(w)
    return 0.45 * h + 0.04 * h * np.sin(cols / 9.0 + phase) + 0.061 * cols


# ---------------------------------------------------------------- NumPy reference loop


def numpy_taper_centre(seg, taper):
    """Raised-cosine ends and taper-weighted centring, written from the med docstring."""
    m = seg.shape[-1]
    i = np.arange(m)
    t = np.minimum(i + 1, m - i) / (taper + 1)
    win = np.where(t < 1, 0.5 - 0.5 * np.cos(np.pi * np.clip(t, 0, 1)), 1.0)
    mu = (seg * win).sum(-1, keepdims=True) / win.sum()
    return win * (seg - mu)


def numpy_med_system(I, W, taper, axis=0):
    """R, b and Σ_j k_j of eqs. (22)–(24) (correction 5) with explicit loops over k, l, j, i."""
    segs = I.T if axis == 0 else I
    X = numpy_taper_centre(segs, taper)  # (N segments, M samples)
    N, M = X.shape
    L = len(W)
    Mf = M + L - 1

    def x(i, j):
        return X[j, i] if 0 <= i < M else 0.0

    B = np.zeros((N, Mf))
    for j in range(N):
        for i in range(Mf):
            B[j, i] = sum(W[k] * x(i - k, j) for k in range(L))
    b = B - B.mean(axis=1, keepdims=True)
    U = (b**2).sum(1)
    K = (b**4).sum(1) / U**2
    R = np.zeros((L, L))
    rhs = np.zeros(L)
    for k in range(L):
        for j in range(N):
            rhs[k] += sum(b[j, i] ** 3 * x(i - k, j) for i in range(Mf)) / U[j] ** 2
        for l in range(L):
            for j in range(N):
                R[k, l] += K[j] / U[j] * sum(x(i - l, j) * x(i - k, j) for i in range(Mf))
    return R, rhs, K.sum()


def numpy_med_step(I, W, taper, axis=0):
    """One update of eqs. (22)–(24): W ← R⁻¹b / ‖R⁻¹b‖."""
    R, rhs, ksum = numpy_med_system(I, W, taper, axis)
    Wn = np.linalg.solve(R, rhs)
    return Wn / np.linalg.norm(Wn), ksum


def mirror_basis(L):
    """Columns: e_k + e_{L−1−k} (k < L/2), and e_{(L−1)/2} for odd L: the symmetric filters."""
    cols = []
    for k in range((L + 1) // 2):
        c = np.zeros(L)
        c[k] = c[L - 1 - k] = 1.0
        cols.append(c)
    return np.stack(cols, axis=1)


@pytest.mark.parametrize("axis, shape, L", [(0, (40, 12), 9), (1, (11, 36), 8)])
def test_symmetric_update_equals_numpy_projected_solve(axis, shape, L):
    """Linear-phase MED: the stationarity condition projected on symmetric filters."""
    h, w = shape
    rng = np.random.default_rng(5)
    centre = wavy_centre(h, w) if axis == 0 else wavy_centre(w, h)
    I = stripe_image(h, w, centre, noise=2.0) if axis == 0 else stripe_image(w, h, centre).T
    W = rng.normal(size=L)
    W /= np.linalg.norm(W)
    R, rhs, _ = numpy_med_system(I, W, 3, axis)
    P = mirror_basis(L)
    ref = P @ np.linalg.solve(P.T @ R @ P, P.T @ rhs)
    ref /= np.linalg.norm(ref)
    pb = med_prepare(jnp.asarray(I), axis=axis, L=L, taper=3)
    Wn, _, _ = med_update(jnp.asarray(W), pb, loading=0.0, symmetric=True)
    np.testing.assert_allclose(np.asarray(Wn), ref, atol=1e-10)
    np.testing.assert_allclose(np.asarray(Wn), np.asarray(Wn)[::-1], atol=1e-14)


@pytest.mark.parametrize("axis, shape", [(0, (40, 12)), (1, (11, 36)), (0, (33, 7))])
def test_update_equals_numpy_loop(axis, shape):
    h, w = shape
    rng = np.random.default_rng(3)
    centre = wavy_centre(h, w) if axis == 0 else wavy_centre(w, h)
    I = stripe_image(h, w, centre, noise=2.0) if axis == 0 else stripe_image(w, h, centre).T
    I = I + rng.normal(0, 1.0, I.shape)
    L, taper = 9, 3
    W = rng.normal(size=L)
    W /= np.linalg.norm(W)
    ref, ksum = numpy_med_step(I, W, taper, axis)
    pb = med_prepare(jnp.asarray(I), axis=axis, L=L, taper=taper)
    Wn, S, _ = med_update(jnp.asarray(W), pb, loading=0.0)
    # float64, L = 9, smooth data: the FFT path agrees with the loops to rounding.
    np.testing.assert_allclose(np.asarray(Wn), ref, atol=1e-10)
    np.testing.assert_allclose(float(S), ksum, rtol=1e-12)
    # The reported objective (direct convolution) agrees with the FFT statistics.
    obj = med_objective(jnp.asarray(W), jnp.asarray(I), axis=axis, form="paper", taper=taper)
    np.testing.assert_allclose(float(obj), (ksum - 3) ** 2, rtol=1e-11)


def test_fft_length_is_smallest_5_smooth():
    def smooth(n):
        for p in (2, 3, 5):
            while n % p == 0:
                n //= p
        return n == 1

    for n in range(1, 1200):
        expected = next(k for k in range(n, 2 * n + 2) if smooth(k))
        assert med_fft.fft_length(n) == expected
    assert med_fft.fft_length(480 + 240 - 1) == 720


# ---------------------------------------------------------------- fixed point properties


def tangential(g, W):
    return g - np.dot(g, W) * W


@pytest.mark.parametrize("form", ["paper", "normalized"])
def test_fixed_point_is_stationary_on_sphere(form):
    h, w = 64, 40
    I = jnp.asarray(stripe_image(h, w, wavy_centre(h, w), speckle=0.2, noise=1.0, seed=1))
    L = 16
    res = med(I, L=L, init="impulse", tol=1e-13, max_steps=400, loading=0.0)
    assert bool(res.converged)
    grad = jax.grad(lambda W: med_objective(W, I, form=form))
    W0 = np.asarray(initial_filter("impulse", L, jnp.float64))
    g0 = tangential(np.asarray(grad(jnp.asarray(W0))), W0)
    W = np.asarray(res.filter)
    g = tangential(np.asarray(grad(jnp.asarray(W))), W)
    assert np.all(np.isfinite(g))
    # Converged to 1e-13 in kurtosis: the tangential gradient is ~1e-6 of its start value
    # (it goes like the square root of the objective change).
    assert np.linalg.norm(g) < 1e-5 * np.linalg.norm(g0)
    # And it is a maximum along the sphere: small tangential moves do not increase O.
    rng = np.random.default_rng(0)
    o = float(med_objective(jnp.asarray(W), I, form=form))
    for _ in range(5):
        d = tangential(rng.normal(size=L), W)
        Wp = W + 1e-3 * d / np.linalg.norm(d)
        assert float(med_objective(jnp.asarray(Wp / np.linalg.norm(Wp)), I, form=form)) <= o


def test_symmetric_fixed_point_is_stationary_among_symmetric_filters():
    """At the linear-phase fixed point, jax.grad of eq. (19) projected on the symmetric
    filters is normal to the sphere: no symmetric unit filter nearby is better."""
    h, w = 64, 40
    I = jnp.asarray(stripe_image(h, w, wavy_centre(h, w), speckle=0.2, noise=1.0, seed=1))
    L = 16
    res = med(I, L=L, tol=1e-13, max_steps=400, loading=0.0, symmetric=True)
    assert bool(res.converged)
    W = np.asarray(res.filter)
    np.testing.assert_allclose(W, W[::-1], atol=1e-12)
    assert float(res.delay) == (L - 1) / 2
    P = mirror_basis(L)
    proj = P @ np.linalg.solve(P.T @ P, P.T)  # orthogonal projector on symmetric filters
    grad = jax.grad(lambda W: med_objective(W, I))
    flat = np.full(L, 1 / np.sqrt(L))
    g0 = tangential(proj @ np.asarray(grad(jnp.asarray(flat))), flat)
    g = tangential(proj @ np.asarray(grad(jnp.asarray(W))), W)
    assert np.linalg.norm(g) < 1e-5 * np.linalg.norm(g0)
    o = float(med_objective(jnp.asarray(W), I))
    rng = np.random.default_rng(1)
    for _ in range(5):
        d = tangential(proj @ rng.normal(size=L), W)
        Wp = W + 1e-3 * d / np.linalg.norm(d)
        assert float(med_objective(jnp.asarray(Wp / np.linalg.norm(Wp)), I)) <= o


@pytest.mark.parametrize("init", ["flat", "impulse"])
def test_kurtosis_rises_monotonically(init):
    h, w = 120, 80
    I = stripe_image(h, w, wavy_centre(h, w), sigma=2.5, speckle=0.3, noise=2.0, seed=2)
    I = jnp.asarray(gaussian_filter1d(I, 1.5, axis=0))  # defocus: something to deconvolve
    pb = med_prepare(I, axis=0)
    W = initial_filter(init, pb.L, I.dtype)
    history = []
    for _ in range(25):
        W, S, excess = med_update(W, pb, loading=1e-9)
        history.append(float(S))
    history = np.asarray(history)
    assert np.all(np.diff(history) >= -1e-9 * history[1:])
    assert history[-1] > 2 * history[0]  # the sharpening is substantial, not rounding


def test_kurtosis_rises_monotonically_on_a_rendered_scene():
    synth = pytest.importorskip("cslx.sim")
    from cslx.segmentation.colour import monochrome

    imgs, gt, _ = synth.render_dataset("cross", "sunny", 1, seed=202, power=60.0)
    I = monochrome(imgs[0], jnp.array([1.0, -1.0, 0.0]))[::2, ::2]  # 240×320 keeps it quick
    for axis in (0, 1):
        pb = med_prepare(I, axis=axis)
        W = initial_filter("flat", pb.L, I.dtype)
        history = []
        for _ in range(12):
            W, S, _ = med_update(W, pb, loading=1e-9)
            history.append(float(S))
        history = np.asarray(history)
        assert np.all(np.diff(history) >= -1e-9 * history[1:])
        assert history[-1] > 1.5 * history[0]


def video(n_frames, h=96, w=72, seed=0):
    """A stripe moving 0.7 px per frame, new noise every frame (~99 % frame overlap)."""
    return np.stack(
        [
            stripe_image(
                h, w, wavy_centre(h, w, phase=0.05 * f) + 0.7 * f, speckle=0.2, seed=seed + f
            )
            for f in range(n_frames)
        ]
    )


def test_warm_start_converges_in_a_few_steps():
    # Fresh speckle and noise every frame: the optimum filter moves a little from frame to
    # frame (L = 48 taps fitted to 200 columns), so the warm start saves steps, not all.
    frames = jnp.asarray(video(4, h=96, w=200))
    cold = med(frames[0], init="impulse")
    assert bool(cold.converged)
    W = cold.filter
    for f in range(1, 4):
        cold_f = med(frames[f], init="impulse")
        warm = med(frames[f], init=W)
        assert bool(warm.converged)
        assert int(warm.steps) <= 7 and int(warm.steps) < int(cold_f.steps)
        np.testing.assert_allclose(float(warm.kurtosis), float(cold_f.kurtosis), rtol=2e-2)
        W = warm.filter


@pytest.mark.parametrize("axis", [0, 1])
def test_jit_vmap_plain_agree(axis):
    frames = video(3, h=48, w=40)
    if axis == 1:
        frames = frames.transpose(0, 2, 1)
    frames = jnp.asarray(frames)
    fn = functools.partial(med, axis=axis, init="impulse")
    batched = jax.vmap(fn)(frames)
    jitted = jax.jit(fn)
    for f in range(3):
        plain = fn(frames[f])
        again = jitted(frames[f])
        for res in (again, jax.tree.map(lambda a, f=f: a[f], batched)):
            np.testing.assert_allclose(np.asarray(res.output), np.asarray(plain.output), atol=1e-10)
            np.testing.assert_allclose(np.asarray(res.filter), np.asarray(plain.filter), atol=1e-10)
            np.testing.assert_allclose(float(res.delay), float(plain.delay), atol=1e-9)
            assert int(res.steps) == int(plain.steps)
        assert np.all(np.isfinite(np.asarray(plain.output)))


def test_axis_1_is_the_transpose_of_axis_0():
    I = jnp.asarray(stripe_image(56, 44, wavy_centre(56, 44), seed=4))
    a = med(I, axis=0, L=20, init="impulse")
    b = med(I.T, axis=1, L=20, init="impulse")
    np.testing.assert_allclose(np.asarray(b.output).T, np.asarray(a.output), atol=1e-10)
    np.testing.assert_allclose(float(a.delay), float(b.delay), atol=1e-10)


# ---------------------------------------------------------------- delay compensation


def smoothed_peak(B, rough, sigma=1.5):
    """Per column: sub-pixel max of B smoothed by a Gaussian (an independent centre estimate)."""
    Bs = gaussian_filter1d(np.asarray(B), sigma, axis=0)
    out = []
    for j, r in enumerate(np.round(rough).astype(int)):
        k = r - 3 + int(np.argmax(Bs[r - 3 : r + 4, j]))
        y0, y1, y2 = Bs[k - 1 : k + 2, j]
        out.append(k + 0.5 * (y0 - y2) / (y0 - 2 * y1 + y2))
    return np.asarray(out)


def centre_of_mass(B, rough, half=4):
    out = []
    for j, r in enumerate(np.round(rough).astype(int)):
        seg = np.asarray(B)[r - half : r + half + 1, j]
        seg = np.clip(seg - seg.min(), 0, None)
        out.append(np.sum(seg * np.arange(r - half, r + half + 1)) / seg.sum())
    return np.asarray(out)


@pytest.mark.parametrize("init, L", [("flat", None), ("impulse", None), ("impulse", 20)])
def test_delay_compensation_leaves_centre_unbiased(init, L):
    h, w = 160, 96
    truth = 70.0 + 0.137 * np.arange(w) + 3 * np.sin(np.arange(w) / 15)  # every sub-pixel phase
    I = jnp.asarray(stripe_image(h, w, truth, ramp=0.0, seed=1))
    res = med(I, init=init, L=L, tol=1e-6, max_steps=150)
    B = np.asarray(res.output)
    assert B.shape == I.shape
    # The same estimators on the input recover the truth (sanity of the estimators).
    assert abs(np.mean(smoothed_peak(np.asarray(I), truth) - truth)) < 0.01
    err_peak = smoothed_peak(B, truth) - truth
    err_com = centre_of_mass(B, truth) - truth
    # Unbiased: mean error well below 0.05 px; per column the sharpened peak scatters more.
    assert abs(err_peak.mean()) < 0.05 and abs(err_com.mean()) < 0.05
    assert np.max(np.abs(err_peak)) < 0.1


def test_fractional_delay_is_found_exactly():
    """A known fractional-delay filter: the delay estimate and the output alignment."""
    h, w = 120, 48
    truth = np.full(w, 50.3) + 0.05 * np.arange(w)
    I = jnp.asarray(stripe_image(h, w, truth, sigma=2.0, ramp=0.0, noise=0.0, seed=0))
    L, d = 24, 9.37
    k = np.arange(L)
    W = np.exp(-0.5 * ((k - d) / 0.8) ** 2)  # symmetric blur about a fractional delay d
    out, delay, _ = med_apply(I, jnp.asarray(W / np.linalg.norm(W)), axis=0)
    assert abs(float(delay) - d) < 0.02
    assert abs(np.mean(smoothed_peak(out, truth) - truth)) < 0.02


def test_border_spike_guard():
    """A strong vertical gradient (shadow edge at the frame border): the tapered segments
    give no border spike, the stripe stays the output's maximum in every column."""
    h, w = 96, 64
    truth = wavy_centre(h, w)
    rows = np.arange(h)[:, None]
    I = stripe_image(h, w, truth, amp=60, seed=5) + 150.0 * (rows / h) ** 2
    res = med(jnp.asarray(I), init="flat", max_steps=50)
    B = np.asarray(res.output)
    hit = np.abs(np.argmax(B, axis=0) - truth) <= 2
    assert hit.mean() > 0.95
    # Without the guard the zero-padding step wins: every column peaks at the border.
    bare = med(jnp.asarray(I), init="flat", max_steps=50, taper=0)
    peak = np.argmax(np.asarray(bare.output), axis=0)
    assert np.mean((peak < 3) | (peak > h - 4)) > 0.9
    assert float(bare.kurtosis) > float(res.kurtosis)  # the trivial solution is "better"


def steger_rows(B):
    from cslx.segmentation.steger import steger_centres

    c = steger_centres(jnp.asarray(B), sigma=2.0, axis=0)
    return np.where(np.asarray(c.valid), np.asarray(c.pos), np.nan)


@pytest.mark.parametrize("taps", [(-0.3, -0.45, 0.85), (-0.2, -0.35, -0.45, 0.8)])
def test_ridge_delay_is_unbiased_for_a_one_sided_filter(taps):
    """The band bias of issue 13: for a one-sided (edge-enhancing) filter the correlation
    peak is not where the detector sees the filtered ridge; the ridge delay is."""
    h, w = 64, 96
    truth = 26.0 + 0.137 * np.arange(w) + 2 * np.sin(np.arange(w) / 11)
    I = jnp.asarray(stripe_image(h, w, truth, sigma=1.0, ramp=0.0, speckle=0.1, seed=3))
    assert abs(np.nanmedian(steger_rows(I) - truth)) < 0.02  # the detector itself is unbiased
    W = np.zeros(16)
    W[4 : 4 + len(taps)] = taps
    W = jnp.asarray(W / np.linalg.norm(W))
    out_x, d_x, _ = med_apply(I, W, delay="xcorr")
    out_r, d_r, _ = med_apply(I, W, delay="ridge")
    err_x = np.nanmedian(steger_rows(out_x) - truth)
    err_r = np.nanmedian(steger_rows(out_r) - truth)
    assert abs(err_x) > 0.3  # the old estimate is off by a large fraction of a pixel
    assert abs(err_r) < 0.05
    assert abs(float(d_r) - float(d_x)) == pytest.approx(abs(err_x - err_r), abs=0.02)


def test_band_med_agrees_with_full_frame_med():
    """MED on a 64-row band (short segments, L = 16) gives the full frame's centres."""
    H, w = 160, 96
    truth = 70.0 + 0.137 * np.arange(w) + 2 * np.sin(np.arange(w) / 11)
    I = jnp.asarray(stripe_image(H, w, truth, speckle=0.3, seed=4))
    full = med(I, delay="ridge")
    c_full = steger_rows(full.output)
    s0 = 48
    band = med(I[s0 : s0 + 64], L=16, delay="ridge", max_steps=60)
    c_band = steger_rows(band.output) + s0
    assert np.mean(np.isfinite(c_band)) > 0.95
    assert abs(np.nanmedian(c_band - c_full)) < 0.05
    assert abs(np.nanmedian(c_band - truth)) < 0.05 and abs(np.nanmedian(c_full - truth)) < 0.05


def skewed_stripe_image(h, w, centre, seed):
    """A stripe whose profile has a shoulder on one side (a bead's flank), plus noise."""
    rng = np.random.default_rng(seed)
    r = np.arange(h)[:, None] - np.asarray(centre)[None, :]
    core = 100 * np.exp(-0.5 * (r / 1.6) ** 2)
    shoulder = 35 * np.exp(-0.5 * ((r - 2.5) / 2.5) ** 2)
    light = 20 * (1 + 0.5 * np.cos(np.pi * np.arange(h)[:, None] / h))
    return core + shoulder + light + 0.5 * rng.standard_normal((h, w))


def test_symmetric_band_med_agrees_with_full_frame_med():
    """Issue 13: MED on a 64-row band with a linear-phase filter (delay exactly (L−1)/2)
    gives the full frame's centres. On a stripe with a one-sided shoulder the band's
    filter moves the centre towards the core, not away from it (full-frame MED keeps
    Steger's shoulder bias by construction of its ridge delay). Linear-phase MED has more
    than one fixed point on these stripes: from another frame's filter it can reach a
    two-lobed filter that copies the stripe 3 px away; that failure and its guard are
    tested in test_med_bands.py."""
    H, w = 160, 128
    truth = 70.0 + 0.137 * np.arange(w) + 2 * np.sin(np.arange(w) / 11)
    s0 = 48
    I = jnp.asarray(stripe_image(H, w, truth, speckle=0.3, seed=4))
    c_full = steger_rows(med(I).output)
    band = med(I[s0 : s0 + 64], L=16, symmetric=True, max_steps=100)
    assert bool(band.converged) and float(band.delay) == 7.5
    c_band = steger_rows(band.output) + s0
    assert np.mean(np.isfinite(c_band)) > 0.95
    assert abs(np.nanmedian(c_band - c_full)) < 0.05

    S = jnp.asarray(skewed_stripe_image(H, w, truth, seed=7))
    bias_full = np.nanmedian(steger_rows(med(S).output) - truth)
    band = med(S[s0 : s0 + 64], L=16, symmetric=True, max_steps=100)
    bias_band = np.nanmedian(steger_rows(band.output) + s0 - truth)
    assert 0 <= bias_band <= bias_full


@pytest.mark.parametrize("axis, L", [(0, 17), (1, 15)])
def test_odd_linear_phase_output_is_the_shifted_convolution(axis, L):
    """Issue 13: with odd L a linear-phase filter's delay (L − 1)/2 is a whole sample, and
    `med` reads its output from B (`med_fft.centre_output`) instead of a Fourier shift
    (`med_fft.shifted_output`): the same values, the same filter and steps."""
    h, w = 64, 40
    I = stripe_image(h, w, wavy_centre(h, w), speckle=0.3, seed=3)
    I = jnp.asarray(I if axis == 0 else I.T)
    pb = med_prepare(I, axis=axis, L=L)
    rng = np.random.default_rng(2)
    half = rng.normal(size=(L + 1) // 2)
    W = jnp.asarray(np.concatenate([half, half[: L // 2][::-1]]))
    W = W / jnp.linalg.norm(W)
    st = med_fft.stats(W, pb)
    ref = np.asarray(med_fft.shifted_output(-W, jnp.asarray((L - 1) / 2), pb))
    out = np.asarray(med_fft.centre_output(st, -1.0, pb))
    np.testing.assert_allclose(out, ref, atol=1e-9 * np.abs(ref).max())
    r = med(I, axis=axis, L=L, symmetric=True, max_steps=5)
    assert float(r.delay) == (L - 1) / 2
    st = med_fft.stats(r.filter, pb)
    ref = np.asarray(med_fft.shifted_output(r.filter, r.delay, pb))
    np.testing.assert_allclose(np.asarray(r.output), ref.T if axis == 0 else ref, atol=1e-9 * 100)
    with pytest.raises(ValueError, match="whole sample"):
        med_fft.centre_output(st, 1.0, med_prepare(I, axis=axis, L=L + 1))


@pytest.mark.parametrize("m, L", [(64, 16), (128, 16), (40, 10)])
def test_stats_is_the_full_convolution_s_statistics(m, L):
    """Issue 13: `med_fft.stats` selects the full convolution (m + L − 1 of the n FFT
    samples) with a mask, not a slice. Against the direct convolution in NumPy: the
    centred outputs (zero past m + L − 1), U_j, the weights of eq. (22) and the kurtosis."""
    n_seg = 7
    I = stripe_image(m, n_seg, np.full(n_seg, m / 2.3), speckle=0.3, seed=5)
    pb = med_prepare(jnp.asarray(I), axis=0, L=L)
    assert pb.n > m + L - 1  # the mask selects part of the FFT length
    W = np.random.default_rng(1).normal(size=L)
    W /= np.linalg.norm(W)
    st = med_fft.stats(jnp.asarray(W), pb)
    X = np.asarray(pb.X)
    B = np.stack([np.convolve(x, W) for x in X])  # (s, m + L − 1), the full convolution
    b = B - B.mean(axis=1, keepdims=True)
    U, F = (b**2).sum(1), (b**4).sum(1)
    k = F / U**2
    got = np.stack([np.asarray(st.ba), np.asarray(st.bb)], 1).reshape(-1, pb.n)[:n_seg]
    np.testing.assert_allclose(got[:, : m + L - 1], b, atol=1e-10 * np.abs(b).max())
    assert np.all(got[:, m + L - 1 :] == 0)
    p = pb.Z.shape[0]  # the weights list the even segments, then the odd ones
    order = np.r_[np.arange(0, n_seg, 2), np.arange(1, n_seg, 2)]
    live = np.r_[np.arange(p), p + np.arange(n_seg // 2)]
    np.testing.assert_allclose(np.asarray(st.w)[live], (k / U)[order], rtol=1e-9)
    np.testing.assert_allclose(np.asarray(st.v)[live], (1 / U**2)[order], rtol=1e-9)
    np.testing.assert_allclose(float(st.ratio_sum), k.sum(), rtol=1e-9)
    np.testing.assert_allclose(float(st.excess), np.mean((m + L - 1) * k - 3), rtol=1e-9)


# ---------------------------------------------------------------- dtypes and errors


def test_float32_agrees_with_float64():
    h, w = 96, 80
    I = stripe_image(h, w, wavy_centre(h, w), speckle=0.2, seed=6)
    r64 = med(jnp.asarray(I, jnp.float64), init="impulse", loading=1e-5)
    r32 = med(jnp.asarray(I, jnp.float32), init="impulse", loading=1e-5)
    assert r32.output.dtype == jnp.float32 and r32.filter.dtype == jnp.float32
    assert int(r32.steps) == int(r64.steps)
    # Same loading, same number of steps: float32 rounding (6e-8) amplified by the
    # conditioning of R gives ~1e-6 on the filter (measured 1.0e-6; docs/metrics.md: 6e-6).
    np.testing.assert_allclose(np.asarray(r32.filter), np.asarray(r64.filter), atol=2e-5)
    scale = float(jnp.max(jnp.abs(r64.output)))
    np.testing.assert_allclose(np.asarray(r32.output), np.asarray(r64.output), atol=5e-5 * scale)
    assert abs(float(r32.delay) - float(r64.delay)) < 1e-3


def test_bad_inputs_raise_clear_errors():
    I = jnp.zeros((20, 10))
    with pytest.raises(ValueError, match="shape"):
        med(jnp.zeros((20, 10, 3)))
    with pytest.raises(ValueError, match="filter length"):
        med(I, L=30)
    with pytest.raises(ValueError, match="axis"):
        med(I, axis=2)
    with pytest.raises(ValueError, match="init"):
        med(I, init="dirac")
    with pytest.raises(ValueError, match="initial filter"):
        med(I, L=5, init=np.ones(4))
    with pytest.raises(ValueError, match="delay"):
        med(I, L=5, delay="peak")
    with pytest.raises(ValueError, match="symmetric"):
        med(I, L=5, delay="centre")


@pytest.mark.parametrize("warm", [False, True])
def test_unrolled_fixed_point_is_the_solver_loop(warm):
    """`med`'s straight-line fixed point (≤ `UNROLL_STEPS` steps) takes the solver's
    iterates, stopping rule and step count (from the converged filter it stops early)."""
    import optimistix as optx

    from cslx.segmentation import med as med_module

    I = jnp.asarray(stripe_image(64, 96, 30 + 3 * np.sin(np.arange(96) / 9), seed=3))
    pb = med_prepare(I, axis=0, L=16)

    def step(y, args):
        W_new, st = med_fft.update(y[0], args, 1e-9, True)
        return W_new, st.ratio_sum

    W0 = med(I, axis=0, L=16, symmetric=True, max_steps=60).filter if warm else "flat"
    y0 = (initial_filter(W0, 16, I.dtype), jnp.zeros((), I.dtype))
    norm, tol = med_module._kurtosis_change, 1e-4
    seen = set()
    for k in range(1, med_module.UNROLL_STEPS + 1):
        y, steps, done = med_module._unrolled(step, y0, pb, tol, k)
        solver = optx.FixedPointIteration(rtol=tol, atol=tol * 1e-6, norm=norm)
        sol = optx.fixed_point(step, solver, y0, args=pb, max_steps=k, throw=False)
        assert int(steps) == int(sol.stats["num_steps"])
        assert bool(done) == bool(sol.result == optx.RESULTS.successful)
        np.testing.assert_allclose(np.asarray(y[0]), np.asarray(sol.value[0]), atol=1e-12)
        seen.add((int(steps), bool(done)))
    assert any(done for _, done in seen) == warm  # the stopping rule was exercised


def test_static_centre_delay_is_the_traced_shift():
    """`shifted_output` with a Python-number delay (constant phase) equals the traced one."""
    I = jnp.asarray(stripe_image(64, 96, 30 + 3 * np.sin(np.arange(96) / 9), seed=4))
    pb = med_prepare(I, axis=0, L=16)
    W = jnp.asarray(np.hanning(16))
    got = med_fft.shifted_output(W, 7.5, pb)
    ref = jax.jit(med_fft.shifted_output)(W, jnp.asarray(7.5), pb)
    np.testing.assert_allclose(np.asarray(got), np.asarray(ref), rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("symmetric, axis", [(True, 0), (True, 1), (False, 0)])
def test_lagged_step_outputs_the_start_filter_and_steps_once(symmetric, axis):
    """`med`'s ``lag`` (tracking bands, issue 13): the output, delay and kurtosis are those of
    the warm-start filter (`med_apply`), and the returned filter is the one fixed-point step
    that ``max_steps=1`` takes from it."""
    truth = 30 + 3 * np.sin(np.arange(96) / 9)
    I = jnp.asarray(stripe_image(64, 96, truth, speckle=0.2, seed=5))
    I = I if axis == 0 else I.T
    prev = jnp.asarray(stripe_image(64, 96, truth + 0.7, speckle=0.2, seed=6))
    prev = prev if axis == 0 else prev.T
    kw = dict(axis=axis, L=16, symmetric=symmetric)
    W0 = med(prev, max_steps=60, **kw).filter  # the previous frame's filter
    lag = med(I, init=W0, lag=True, **kw)
    one = med(I, init=W0, max_steps=1, tol=1e-12, **kw)
    assert int(lag.steps) == int(one.steps) == 1
    np.testing.assert_allclose(np.asarray(lag.filter), np.asarray(one.filter), atol=1e-12)
    kind = "centre" if symmetric else "ridge"
    out, delay, kurt = med_apply(I, W0, axis=axis, delay=kind)
    np.testing.assert_allclose(np.asarray(lag.output), np.asarray(out), atol=1e-9)
    assert float(lag.delay) == pytest.approx(float(delay), abs=1e-9)
    assert float(lag.kurtosis) == pytest.approx(float(kurt), abs=1e-9)
    # the step moved the filter: the lagged output is not the stepped one
    assert float(jnp.max(jnp.abs(lag.filter - W0))) > 1e-6


@pytest.mark.parametrize("axis", [0, 1])
def test_lagged_step_on_every_other_pair_of_segments(axis):
    """``lag_stride`` (tracking bands, issue 13): the output is the lagged output on every
    segment, the step (and the kurtosis) those of the segments (2j, 2j + 1), j even, alone."""
    truth = 30 + 3 * np.sin(np.arange(96) / 9)
    I = jnp.asarray(stripe_image(64, 96, truth, speckle=0.2, seed=5))
    prev = jnp.asarray(stripe_image(64, 96, truth + 0.7, speckle=0.2, seed=6))
    I, prev = (I, prev) if axis == 0 else (I.T, prev.T)
    kw = dict(axis=axis, L=16, symmetric=True)
    W0 = med(prev, max_steps=60, **kw).filter
    lag = med(I, init=W0, lag=True, **kw)
    strided = med(I, init=W0, lag=True, lag_stride=2, **kw)
    np.testing.assert_allclose(np.asarray(strided.output), np.asarray(lag.output), atol=1e-12)
    keep = np.asarray([j for j in range(96) if (j // 2) % 2 == 0])
    sub = med(I[:, keep] if axis == 0 else I[keep], init=W0, lag=True, **kw)
    np.testing.assert_allclose(np.asarray(strided.filter), np.asarray(sub.filter), atol=1e-12)
    assert float(strided.kurtosis) == pytest.approx(float(sub.kurtosis), abs=1e-9)
    # half the segments give another step than all of them
    assert float(jnp.max(jnp.abs(strided.filter - lag.filter))) > 1e-6


@pytest.mark.parametrize("axis", [0, 1])
def test_lagged_step_refreshed_on_some_frames_only(axis):
    """``refresh`` (`PipelineConfig.roi_med_alternate`, issue 13): True is the lagged step
    (filter, kurtosis, output); False carries the start filter (0 steps, NaN kurtosis) and
    outputs that filter as the lagged step does."""
    truth = 30 + 3 * np.sin(np.arange(96) / 9)
    I = jnp.asarray(stripe_image(64, 96, truth, speckle=0.2, seed=5))
    prev = jnp.asarray(stripe_image(64, 96, truth + 0.7, speckle=0.2, seed=6))
    I, prev = (I, prev) if axis == 0 else (I.T, prev.T)
    kw = dict(axis=axis, L=16, symmetric=True, lag=True, lag_stride=2)
    W0 = med(prev, max_steps=60, axis=axis, L=16, symmetric=True).filter
    lag = med(I, init=W0, **kw)
    on = med(I, init=W0, refresh=True, **kw)
    off = med(I, init=W0, refresh=False, **kw)
    np.testing.assert_allclose(np.asarray(on.filter), np.asarray(lag.filter), atol=1e-12)
    assert float(on.kurtosis) == pytest.approx(float(lag.kurtosis), abs=1e-9)
    assert int(on.steps) == 1 and int(off.steps) == 0 and np.isnan(float(off.kurtosis))
    np.testing.assert_array_equal(np.asarray(off.filter), np.asarray(W0))
    for r in (on, off):
        np.testing.assert_allclose(np.asarray(r.output), np.asarray(lag.output), atol=1e-9)
    with pytest.raises(ValueError, match="refresh"):
        med(I, init=W0, axis=axis, L=16, symmetric=True, refresh=True)


@pytest.mark.parametrize("m, L", [(64, 16), (7, 3), (10, 4), (12, 12)])
def test_shift_matrix_is_the_fourier_shift(m, L):
    """`med_fft.shift_matrix` (the lagged band output as one matrix product, issue 13) is
    `shifted_output` for a static delay: the first m samples of the circular convolution
    with W, shifted in the Fourier domain, for every segment (an odd count included)."""
    rng = np.random.default_rng(m + L)
    X = jnp.asarray(rng.normal(size=(5, m)))
    W = jnp.asarray(rng.normal(size=L))
    pb = med_fft.prepare(X, L)
    for delay in ((L - 1) / 2, 1.25):
        M = med_fft.shift_matrix(W, delay, m, pb.n)
        assert M.shape == (m, m)
        ref = np.asarray(med_fft.shifted_output(W, delay, pb))
        np.testing.assert_allclose(np.asarray(X @ M.T), ref, atol=1e-12 * np.abs(ref).max())


@pytest.mark.parametrize("n, L", [(80, 16), (144, 16), (45, 7), (720, 240)])
def test_short_transforms_are_numpy_ffts(n, L):
    """The band MED step's short transforms as constant-matrix products (n ≤
    `med_fft.DFT_MATRIX_MAX`; issue 13), or FFTs above it: a filter's spectrum, the first L
    samples of an inverse real FFT (complex and real half-spectra, odd n included), the
    linear-phase system of `update` and its solve, and the sign of `centre_sign`."""
    rng = np.random.default_rng(n + L)
    W = rng.normal(size=L)
    spec = np.asarray(med_fft.filter_spectrum(jnp.asarray(W), n))
    np.testing.assert_allclose(spec, np.fft.fft(W, n), atol=1e-12 * L)
    f = n // 2 + 1
    G = rng.normal(size=f) + 1j * rng.normal(size=f)
    for g in (G, G.real):
        got = np.asarray(med_fft.irfft_head(jnp.asarray(g), n, L))
        np.testing.assert_allclose(got, np.fft.irfft(g, n)[:L], atol=1e-14 * f)
    r = np.exp(-np.arange(L) / 3.0) + 1e-3
    P = med_fft.symmetric_basis(L)
    gram = (jnp.asarray(r) @ jnp.asarray(med_fft._symmetric_gram(L))).reshape(P.shape[1], -1)
    A = P.T @ np.asarray(med_fft.toeplitz(jnp.asarray(r))) @ P
    np.testing.assert_allclose(np.asarray(gram), A, atol=1e-13)
    b = rng.normal(size=P.shape[1])
    x = np.asarray(med_fft.spd_solve(jnp.asarray(A), jnp.asarray(b)))
    np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=1e-9, atol=1e-9 * np.abs(x).max())
    X = jnp.asarray(rng.normal(size=(6, n - L + 1)))
    pb = med_fft.prepare(X, L)
    w = jnp.asarray(rng.uniform(0.5, 2.0, size=2 * pb.Pa.shape[0]))
    Pw = np.asarray(w[: pb.Pa.shape[0]] @ pb.Pa + w[pb.Pa.shape[0] :] @ pb.Pb)
    Ws = W + W[::-1]
    c = np.fft.irfft(np.fft.rfft(Ws, pb.n) * Pw, pb.n)
    mid = c[(L - 1) // 2] + c[L // 2]
    assert float(med_fft.centre_sign(jnp.asarray(Ws), w, pb)) == (1.0 if mid >= 0 else -1.0)
    assert float(med_fft.centre_sign(-jnp.asarray(Ws), w, pb)) == (-1.0 if mid > 0 else 1.0)
