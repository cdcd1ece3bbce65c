"""Minimum entropy deconvolution of the stripe image (section 3.2, Table 2, eqs. (18)–(26)).

Each segment of the monochrome image (a column for the horizontal stripe, ``axis=0``; a row
for the vertical stripe, ``axis=1``) is filtered by one shared FIR filter W of length L,

    B_ij = Σ_k W_k X_{i−k, j}                                               (18)

and W (‖W‖ = 1, eq. (20)) maximises the kurtosis of the output columns, eq. (19),

    O(W) = ( Σ_j Σ_i (B_ij − μ_j)⁴ / (Σ_i (B_ij − μ_j)²)² − 3 )².            (19)

Setting the gradient to zero gives the fixed point of eqs. (22)–(24), in the form of
docs/corrections.md, 5 (X the centred input, U_j = Σ_i (B_ij − μ_j)², k_j = Σ(B−μ)⁴/U_j²):

    R_kl = Σ_j (k_j / U_j) Σ_i X_{i−l,j} X_{i−k,j},
    b_k  = Σ_j U_j⁻²  Σ_i (B_ij − μ_j)³ X_{i−k,j},
    W ← R⁻¹ b / ‖R⁻¹ b‖.

R is a weighted sum of segment autocorrelations (Toeplitz), b a weighted sum of
cross-correlations: both are accumulated in the Fourier domain (two segments packed in one
complex FFT, length the smallest 5-smooth n ≥ M + L − 1, e.g. 720 for M = 480, L = 240),
so one iteration costs one inverse and one forward batched FFT plus an L×L Toeplitz
solve (small diagonal loading; Levinson's O(L²) recursion on the CPU, a Cholesky
factorisation elsewhere: `med_fft.toeplitz_solve`). `optimistix.fixed_point` with
`FixedPointIteration` runs the iteration.

Objective forms. The literal eq. (19) and the normalised form of correction 4 (mean over
segments of the sample excess kurtosis (M+L−1) k_j − 3) are both increasing functions of
Σ_j k_j whenever Σ_j k_j > 3, so they have the same stationary points and the same update;
`med_objective` evaluates either. `MEDResult.kurtosis` reports the normalised one.

Choices where the paper is vague:

- Border spike (correction 6). With full convolution of a zero-padded segment, a
  derivative-like filter turns the step at each end of every column into an identical
  spike: a trivial, highly kurtotic solution. Each segment is therefore centred with a
  taper-weighted mean and multiplied by raised-cosine ramps of ``taper`` samples
  (default 8) at both ends, so it starts and ends at zero with no step; the full
  convolution (all M + L − 1 outputs) is then used, which keeps every stripe row, unlike the
  valid part (only M − L + 1 = 241 rows for L = M/2). Stripes inside the ramps are
  attenuated, not moved much. Measured limit (tests/test_med.py): a background gradient
  that leaves a segment end ~1.7× the stripe amplitude away from the segment mean is
  handled (without the taper MED locks onto the border in every column); at ~4.4× the
  tapered ends can still win. Longer ``taper`` values trade border
  coverage for robustness.
- Delay (eqs. (25)–(26), correction 6). The filter moves the stripe by its delay d, which
  MED chooses freely. d is the peak of the cross-correlation of B with X summed over
  segments (weighted like R), refined on its band-limited interpolant (Newton on
  c'(d) = 0, unbiased for a symmetric response, unlike a 3-point parabola), and undone by a
  Fourier shift: the output is B(i + d), aligned with the input rows. The filter's sign is
  fixed so that the correlation is positive (the stripe stays bright). The correlation peak
  is the delay of a symmetric (linear-phase) filter only; MED's filter is free, and on short
  segments (the tracking bands) it becomes one-sided and edge-enhancing, whose ridge a
  detector of scale σ sees 1–2 px from the correlation peak (issue 13; on full 640×480
  frames 0.05–0.15 px). ``delay="ridge"`` (the default since issue 13) measures the delay
  where it matters: the median displacement of the stripe's ridge at scale σ from input to
  output segments (`med_fft.ridge_delay`). Evidence for the default (results/bench_speed.md,
  held-out video frames): median |centre − truth| of full-frame MED + Steger 0.108 px with
  "ridge" against 0.144 px with "xcorr"; in 64–128-sample bands "xcorr" is 1–2 px off.
- Linear-phase MED (``symmetric=True``, issue 13). On short segments (the 64-row and
  128-column bands of the pipeline) the free filter converges to a one-sided,
  edge-enhancing filter: its output ridge moves with each segment's own stripe profile, so
  no single delay undoes it, and band centres differed from full-frame MED by up to 0.18 px
  (median over a frame). Restricting the filter to W_k = W_{L−1−k} (the stationarity
  condition projected on those filters, `med_fft.update`) removes the cause: a symmetric
  filter delays every frequency by exactly (L − 1)/2, which is undone with no estimate
  (``delay="centre"``), and it moves the ridge of a symmetric stripe profile not at all.
  On dev frames (rendered sunny video, seeds 3–4) the band centres then agree with
  full-frame MED within 0.04 px and converge in 12–21 steps from the flat start (3–6 from
  the previous frame's filter, to the same fixed point: centres within 0.001 px median).
- Start (Table 2, step 1): ``init="flat"`` is W = 1/√L; ``"impulse"`` a unit impulse at
  L//2 (the usual MED start); an (L,) array warm-starts from the previous frame's filter.
  Table 2, step 2 cites "Equation (11)" for the output: it means eq. (18).
- Stopping (Table 2, step 5): when the relative change of Σ_j k_j between two iterations is
  below ``tol``, or after ``max_steps``. The filter itself converges more slowly than the
  kurtosis (flat directions of the objective), so a tolerance on the filter would cost
  many more iterations for no visible change of the output.
- Speed: an iteration is one packed inverse FFT, one forward FFT and an L×L Toeplitz
  solve. On the CPU the solve is Levinson's recursion (0.12 ms for L = 320, against 0.45 ms
  for LAPACK's Cholesky; the cold full frame 23.3 → 20.8 ms median, issue 13). The
  linear-phase (``symmetric``) step and other platforms use a Cholesky through LAPACK
  (OpenBLAS): for L > 256 OpenBLAS's threads, on a loaded machine, made it 100–1000×
  slower in our measurements; run with ``OPENBLAS_NUM_THREADS=1``.

Every function here is pure on one frame; `med` is jit-compiled (equinox filter_jit:
strings and ints are static) and vmap-able over frames. Float32 is the speed path.
"""

from __future__ import annotations

import functools
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from . import med_fft as _f
from .colour import DEFAULT_FORM, Form

__all__ = [
    "MEDResult",
    "med",
    "med_apply",
    "med_objective",
    "med_output",
    "med_prepare",
    "med_update",
    "default_filter_length",
    "initial_filter",
    "stripe_segments",
]

DEFAULT_TAPER = 8


class MEDResult(eqx.Module):
    """Result of `med` on one frame (leading batch axes under vmap).

    Attributes:
        output: (H, W) deconvolved image B, delay-compensated, aligned with the input.
        filter: (L,) unit-norm FIR filter W (sign: stripe bright).
        delay: sub-pixel delay d of the filter in pixels (undone in ``output``).
        kurtosis: mean sample excess kurtosis of the filtered segments (normalised form).
        steps: fixed-point iterations taken.
        converged: whether the tolerance was met within ``max_steps``.
    """

    output: Float[Array, "h w"]
    filter: Float[Array, " L"]
    delay: Float[Array, ""]
    kurtosis: Float[Array, ""]
    steps: Int[Array, ""]
    converged: Bool[Array, ""]


def default_filter_length(segment_length: int) -> int:
    """L = 50 % of the segment length (the paper's choice, correction 7)."""
    return max(2, segment_length // 2)


def _check_image(I) -> Array:
    I = jnp.asarray(I)
    if I.ndim != 2:
        raise ValueError(
            f"med expects one monochrome frame of shape (H, W), got shape {I.shape}; "
            "convert RGB with cslx.segmentation.colour.monochrome and vmap over frames"
        )
    if not jnp.issubdtype(I.dtype, jnp.floating):
        I = I.astype(jnp.result_type(float))
    return I


def stripe_segments(I: Array, axis: int) -> Array:
    if axis == 0:
        return I.T
    if axis == 1:
        return I
    raise ValueError(f"axis must be 0 (filter down columns) or 1 (along rows), got {axis}")


def _length(I: Array, axis: int, L: int | None) -> int:
    if axis not in (0, 1):
        raise ValueError(f"axis must be 0 (filter down columns) or 1 (along rows), got {axis}")
    m = I.shape[axis]
    L = default_filter_length(m) if L is None else int(L)
    if not 2 <= L <= m:
        raise ValueError(f"filter length L must lie in [2, {m}] for segments of {m}, got {L}")
    return L


def initial_filter(init, L: int, dtype) -> Float[Array, " L"]:
    """Table 2's flat start 1/√L, a centred unit impulse, or a given (L,) filter."""
    if isinstance(init, str):
        if init == "flat":
            return jnp.full((L,), 1.0 / jnp.sqrt(L), dtype)
        if init == "impulse":
            return jnp.zeros((L,), dtype).at[L // 2].set(1.0)
        raise ValueError(f"init must be 'flat', 'impulse' or an (L,) array, got {init!r}")
    W = jnp.asarray(init, dtype)
    if W.shape != (L,):
        raise ValueError(f"initial filter must have shape ({L},), got {W.shape}")
    return W / jnp.linalg.norm(W)


def med_prepare(
    I: Float[Array, "h w"], *, axis: int = 0, L: int | None = None, taper: int = DEFAULT_TAPER
) -> _f.Problem:
    """Per-frame precomputation: centred, tapered segments and their packed FFTs."""
    I = _check_image(I)
    L = _length(I, axis, L)
    X = _f.centre_and_taper(stripe_segments(I, axis), taper)
    return _f.prepare(X, L)


def med_update(
    W: Float[Array, " L"], problem: _f.Problem, loading: float = 0.0, symmetric: bool = False
):
    """One step of eqs. (22)–(24): returns (new unit filter, Σ_j k_j at W, excess kurtosis at W).

    ``symmetric``: the step restricted to linear-phase filters (`med_fft.update`).
    """
    W_new, st = _f.update(W, problem, loading, symmetric)
    return W_new, st.ratio_sum, st.excess


def _default_loading(dtype) -> float:
    # R is a smoothed spectrum of a smooth image: float32 Cholesky needs some loading.
    return 1e-5 if jnp.finfo(dtype).bits <= 32 else 1e-9


def _kurtosis_change(scaled_error):
    # optimistix keeps its error in the default float dtype; match it for float32 under x64.
    return jnp.abs(scaled_error[1]).astype(jnp.result_type(float))


DELAYS = ("ridge", "xcorr", "centre")


def _check_delay(delay, symmetric: bool) -> str:
    if delay is None:
        return "centre" if symmetric else "ridge"
    if delay not in DELAYS:
        raise ValueError(f"delay must be one of {', '.join(DELAYS)}, got {delay!r}")
    if delay == "centre" and not symmetric:
        raise ValueError('delay="centre" is the delay of a symmetric filter: use symmetric=True')
    return delay


def _delay(W, st, pb, delay, ridge_sigma):
    """(delay, sign) of the filter: its centre (symmetric), correlation peak, or ridge."""
    if delay == "centre":
        return jnp.asarray((pb.L - 1) / 2, W.dtype), _f.centre_sign(W, st.w, pb)
    d, sign = _f.peak_delay(W, st.w, pb)
    if delay == "ridge":
        d = _f.ridge_delay(W, st, sign, d, pb, ridge_sigma)
    elif delay != "xcorr":
        raise ValueError(f"delay must be 'xcorr' or 'ridge', got {delay!r}")
    return d, sign


#: Step caps up to this are run as straight-line code (`_unrolled`), not a solver loop.
UNROLL_STEPS = 3


def _unrolled(step, y0, args, tol, max_steps):
    """`optimistix.fixed_point` with `FixedPointIteration` for a small ``max_steps``, unrolled.

    The same iterates, stopping rule and step count (a step whose kurtosis change is within
    tolerance ends the iteration; later steps are computed and discarded), as straight-line
    code for the tracking bands' 2 steps a frame: the steps' ≈ 60 kernels each run the same,
    the solver's loop and bookkeeping go (issue 13: MED on the 64×640 band 2.20 → 2.11 ms,
    300 interleaved calls, load 8–9; small, kept as it costs nothing). Same iterates to
    float32 rounding (filters within 2e-6; tests/segmentation/test_med.py).
    """
    atol = tol * 1e-6
    y, done = y0, jnp.zeros((), bool)
    steps = jnp.zeros((), jnp.int32)
    for _ in range(max_steps):
        new = step(y, args)
        # optimistix: error y − f(y) over atol + rtol·|f(y)|, on the kurtosis component
        rel = _kurtosis_change(((), (y[1] - new[1]) / (atol + tol * jnp.abs(new[1]))))
        y = jax.tree_util.tree_map(functools.partial(jnp.where, done), y, new)
        steps = steps + jnp.where(done, 0, 1)
        done = done | (rel < 1)
    return y, steps, done


@eqx.filter_jit
def _med(
    I,
    W0,
    axis,
    L,
    taper,
    tol,
    max_steps,
    loading,
    delay_kind,
    ridge_sigma,
    symmetric=False,
    lag=False,
    lag_stride=1,
    refresh=None,
):
    pb = med_prepare(I, axis=axis, L=L, taper=taper)
    if lag:
        args = (delay_kind, ridge_sigma, symmetric, lag_stride, refresh)
        return _lagged(pb, W0, axis, loading, *args)

    def step(y, args):
        # y = (filter, Σ_j k_j of the previous filter): the solver's error on the second
        # component is the change of kurtosis between iterations (Table 2, step 5).
        W, _ = y
        pb, loading = args
        W_new, st = _f.update(W, pb, loading, symmetric)
        return W_new, st.ratio_sum

    y0 = (W0, jnp.zeros((), W0.dtype))
    if 0 < max_steps <= UNROLL_STEPS:
        y, steps, converged = _unrolled(step, y0, (pb, loading), tol, max_steps)
        W = y[0]
    else:
        import optimistix as optx  # lazy: a cached start-up never traces this (runtime.compiled)

        solver = optx.FixedPointIteration(rtol=tol, atol=tol * 1e-6, norm=_kurtosis_change)
        sol = optx.fixed_point(
            step, solver, y0, args=(pb, loading), max_steps=max_steps, throw=False
        )
        W = sol.value[0]
        steps, converged = sol.stats["num_steps"], sol.result == optx.RESULTS.successful
    st = _f.stats(W, pb)
    delay, sign = _delay(W, st, pb, delay_kind, ridge_sigma)
    W = W * sign
    if delay_kind == "centre" and L % 2:
        out = _f.centre_output(st, sign, pb)  # a whole-sample delay: a slice, no FFT
    elif delay_kind == "centre":
        out = _f.shifted_output(W, (L - 1) / 2, pb)  # a static delay: a constant phase
    else:
        out = _f.shifted_output(W, delay, pb)
    out = out.T if axis == 0 else out
    return MEDResult(out, W, delay, st.excess, steps, converged)


def med(
    I: Float[Array, "h w"],
    *,
    axis: int = 0,
    L: int | None = None,
    init: Literal["flat", "impulse"] | ArrayLike = "flat",
    tol: float = 1e-4,
    max_steps: int = 30,
    taper: int = DEFAULT_TAPER,
    loading: float | None = None,
    delay: Literal["ridge", "xcorr", "centre"] | None = None,
    ridge_sigma: float = 2.0,
    symmetric: bool = False,
    lag: bool = False,
    lag_stride: int = 1,
    refresh: ArrayLike | None = None,
) -> MEDResult:
    """MED of one monochrome frame by the fixed point of eqs. (22)–(24) (section 3.2).

    Args:
        I: (H, W) monochrome image (float32 for speed, float64 for accuracy).
        axis: 0 runs the filter down each column (horizontal stripe, one centre per
            column); 1 along each row (vertical stripe).
        L: filter length, default 50 % of the segment length (H//2 for axis 0).
        init: ``"flat"`` (Table 2), ``"impulse"`` (centred unit impulse) or an (L,)
            filter to warm-start from (e.g. the previous video frame's ``filter``).
        tol: stop when the relative change of Σ_j k_j (the kurtosis of eq. (19)) between
            two iterations is below ``tol`` (Table 2, step 5).
        max_steps: iteration cap; ``converged`` says whether ``tol`` was met.
        taper: raised-cosine ramp length at the segment ends (border-spike guard).
        loading: diagonal loading of R relative to R_00 (default 1e-5 float32, 1e-9 float64).
        delay: how the filter's delay is measured before it is undone: ``"ridge"`` (default)
            the median displacement of the stripe's ridge seen at scale ``ridge_sigma`` from
            input to output (`med_fft.ridge_delay`); ``"xcorr"`` the peak of the
            output/input cross-correlation (eqs. (25)–(26), correction 6; exact for a
            symmetric filter only); ``"centre"`` (the default with ``symmetric``) exactly
            (L − 1)/2, the delay of a linear-phase filter.
        ridge_sigma: detector scale of the ``"ridge"`` delay (Steger's σ downstream).
        symmetric: restrict W to linear-phase filters W_k = W_{L−1−k} (module notes; the
            pipeline's bands). Meant for short filters on bands: linear-phase MED has
            several fixed points, and with L = M/2 on synthetic full frames it converged to
            filters with two lobes far apart that copy the stripe 28–43 px away;
            `cslx.segmentation.med_bands` checks its band results against the input.
        lag: for video, one step a frame (``init`` the previous frame's filter): the output
            is that of ``init`` itself and ``filter`` is one fixed-point step from it, for
            the next frame (`_lagged`; ``max_steps`` and ``tol`` unused, ``steps`` 1,
            ``converged`` False, ``kurtosis`` at ``init``): one inverse-FFT pass (the
            statistics at the new filter) fewer than ``max_steps=1``.
        lag_stride: with ``lag``, the step (and the statistics: kurtosis, sign, delay) is
            taken on every ``lag_stride``-th pair of segments only; the output still
            filters every segment (`_lagged`).
        refresh: with ``lag`` and a linear-phase filter output by its shift matrix, a
            traced bool: False skips the step (`_lagged`: ``filter`` is ``init``, ``steps``
            0, ``kurtosis`` NaN; the output is still that of ``init``).

    Returns:
        `MEDResult` with the delay-compensated output (same shape as I), the filter, its
        delay, the kurtosis, the number of steps and the convergence flag.
    """
    I = _check_image(I)
    L = _length(I, axis, L)
    W0 = initial_filter(init, L, I.dtype)
    loading = _default_loading(I.dtype) if loading is None else float(loading)
    delay = _check_delay(delay, symmetric)
    args = (int(taper), float(tol), int(max_steps), loading, delay, float(ridge_sigma))
    if int(lag_stride) < 1:
        raise ValueError(f"lag_stride must be a positive integer, got {lag_stride!r}")
    if refresh is not None and not (lag and delay == "centre" and (L % 2 == 0 or lag_stride > 1)):
        raise ValueError("refresh needs lag and a linear-phase filter output by its matrix")
    flags = (bool(symmetric), bool(lag), int(lag_stride))
    return _med(I, W0, axis, L, *args, *flags, None if refresh is None else jnp.asarray(refresh))


def _lagged(pb, W0, axis, loading, delay_kind, ridge_sigma, symmetric, stride=1, refresh=None):
    """`med`'s ``lag``: the output of the warm-start filter W0, and one step from it.

    One fixed-point step W1 = update(W0) needs the output statistics at W0 (`med_fft.update`
    computes them first); those same statistics give W0's delay, sign and kurtosis, and its
    output is one more inverse FFT. A step that is then output costs a third pass (W1's
    statistics) before its output. Both variants take one step a frame from the previous
    frame's filter and share the fixed point (W1 = W0 there); the lagged one filters frame t
    with the filter of the step taken on frame t − 1.

    ``stride`` > 1: the statistics and the step on every stride-th packed pair of segments
    (`med_fft.pairs`), the output on all of them.

    A linear-phase filter (``delay="centre"``) has a static delay, and its output is one
    matrix product with the band (`med_fft.shift_matrix`, the same values as the Fourier
    shift to float rounding); the band's own spectra are then not needed, and only the
    strided pairs are transformed (`med_fft.prepare` on them: the spectra `pairs` would
    slice, bit for bit). Issue 13, band MED alone against the forward and inverse FFT pair
    (`experiments.ab_band_med`, 400 interleaved calls, load 17–19): 480×128 band median
    0.90 → 0.64 ms (p10 0.67 → 0.51, median paired difference −0.22 ms), 64×640 band 0.48
    → 0.48 ms (p10 0.40 → 0.37, paired −0.03 ms); outputs within 1e-6 of their largest
    value, filters identical.
    """
    L, m = pb.L, pb.m
    matrix = delay_kind == "centre" and not (L % 2 and stride == 1)
    if refresh is not None:  # the step on some frames only (`med`'s ``refresh``)
        return _refreshed(pb, W0, axis, loading, symmetric, stride, refresh)
    if stride == 1:
        sub = pb
    elif matrix:
        sub = _strided_segments(pb, stride)
    else:
        sub = _f.pairs(pb, stride)
    W1, st = _f.update(W0, sub, loading, symmetric)
    delay, sign = _delay(W0, st, sub, delay_kind, ridge_sigma)
    if matrix:
        out = _centro_output(_f.shift_matrix(W0 * sign, (L - 1) / 2, m, pb.n), pb.X, axis)
    else:
        if delay_kind == "centre":  # odd L, every segment: a slice of B, no FFT
            out = _f.centre_output(st, sign, pb)
        else:
            out = _f.shifted_output(W0 * sign, delay, pb)
        out = out.T if axis == 0 else out
    # ±W have the same kurtosis and the step keeps W0's orientation: W1 takes W0's sign
    one = jnp.ones((), jnp.int32)
    return MEDResult(out, W1 * sign, delay, st.excess, one, jnp.zeros((), bool))


def _strided_segments(pb, stride):
    """The pairs (2j, 2j + 1), j = 0, k, 2k … of `med_fft.pairs`, prepared (bit for bit)."""
    X = jnp.pad(pb.X, ((0, pb.s % 2), (0, 0))).reshape(-1, 2, pb.m)[::stride]
    return _f.prepare(X.reshape(-1, pb.m), pb.L)


def _refreshed(pb, W0, axis, loading, symmetric, stride, refresh):
    """`_lagged` of a linear-phase filter whose step runs only where ``refresh`` is True
    (`lax.cond`: on the CPU only the chosen branch runs); elsewhere W0 is carried, with the
    sign +1 (the filters carried from frame to frame are oriented by their last step), and
    the band is filtered by the same matrix product. The tracking bands' step on one band a
    frame (`PipelineConfig.roi_med_alternate`, where the measurements are)."""
    L, m = pb.L, pb.m

    def step():
        sub = pb if stride == 1 else _strided_segments(pb, stride)
        W1, st = _f.update(W0, sub, loading, symmetric)
        sign = _f.centre_sign(W0, st.w, sub)
        return W1 * sign, sign, st.excess, jnp.ones((), jnp.int32)

    def keep():
        nan = jnp.full((), jnp.nan, W0.dtype)
        return W0, jnp.ones((), W0.dtype), nan, jnp.zeros((), jnp.int32)

    W1, sign, excess, steps = jax.lax.cond(refresh, step, keep)
    out = _centro_output(_f.shift_matrix(W0 * sign, (L - 1) / 2, m, pb.n), pb.X, axis)
    delay = jnp.asarray((L - 1) / 2, W0.dtype)
    return MEDResult(out, W1, delay, excess, steps, jnp.zeros((), bool))


def _centro_output(M, X, axis):
    """The band filtered by a linear-phase filter's shift matrix M: ``M @ X.T`` (axis 0, as
    (m, s)) or ``X @ M.T`` (axis 1, as (s, m)), with half the multiplications for even m.

    M_ij = g(i − j) with g even (the zero-phase response of a symmetric filter delayed by
    its centre: `med_fft.shift_matrix`), so M is centrosymmetric, M = [[A, B], [JBJ, JAJ]]
    (J the reversal), and M x = [P u + Q w; J (P u − Q w)] with u = x₁ + J x₂,
    w = x₁ − J x₂, P = ½(A + BJ), Q = ½(A − BJ): two products of (m/2)² per segment instead
    of m² (issue 13). The band of rows is multiplied as (m, s) with its samples leading
    (``pb.X.T``; as (s, m) it was slower: alone 149 against 94 µs p10, the full product
    121). Band MED alone (`experiments.ab_band_med --rev main`, 400 interleaved calls, two
    runs at load 10–12): 64×640 band paired −0.017 / −0.020 ms (median 0.440 → 0.425 ms),
    480×128 band −0.067 / −0.082 ms (0.570 → 0.510 ms); outputs within 9e-5 of their
    largest value 144, filters identical. The whole tracking frame (`experiments.ab_tracking
    --rev main`, 300 frames, load 7–11): paired +0.015, −0.080, −0.016 ms, inside the
    load's quartiles (±0.7–3 ms). Its centres moved ≤ 3.1e-5 px (video seed 0, 48 frames);
    one ill-posed frame's bead centre (the cap fit) 0.18 mm (widths ≤ 1e-4 mm). Not kept:
    u and w as one stacked array (one fusion instead of two; paired +0.013 / −0.021 ms on
    the two bands, 400 calls, load 9–10: noise).
    """
    hi = jax.lax.Precision.HIGHEST  # no TF32 on GPUs
    m = M.shape[0]
    if m % 2:
        return jnp.dot(M, X.T, precision=hi) if axis == 0 else jnp.dot(X, M.T, precision=hi)
    k = m // 2
    A, BJ = M[:k, :k], M[:k, k:][:, ::-1]
    P, Q = 0.5 * (A + BJ), 0.5 * (A - BJ)
    if axis == 0:
        X = X.T
        u, w = X[:k] + X[k:][::-1], X[:k] - X[k:][::-1]
        p, q = jnp.dot(P, u, precision=hi), jnp.dot(Q, w, precision=hi)
        return jnp.concatenate([p + q, (p - q)[::-1]], axis=0)
    u, w = X[:, :k] + X[:, k:][:, ::-1], X[:, :k] - X[:, k:][:, ::-1]
    p, q = jnp.dot(u, P.T, precision=hi), jnp.dot(w, Q.T, precision=hi)
    return jnp.concatenate([p + q, (p - q)[:, ::-1]], axis=1)


@eqx.filter_jit
def _apply(I, W, axis, taper, delay_kind, ridge_sigma):
    pb = med_prepare(I, axis=axis, L=W.shape[0], taper=taper)
    st = _f.stats(W, pb)
    delay, sign = _delay(W, st, pb, delay_kind, ridge_sigma)
    out = _f.shifted_output(W * sign, delay, pb)
    return (out.T if axis == 0 else out), delay, st.excess


def med_apply(
    I: Float[Array, "h w"],
    W: Float[Array, " L"],
    *,
    axis: int = 0,
    taper: int = DEFAULT_TAPER,
    delay: Literal["ridge", "xcorr", "centre"] = "ridge",
    ridge_sigma: float = 2.0,
) -> tuple[Float[Array, "h w"], Float[Array, ""], Float[Array, ""]]:
    """Filter a frame with a known MED filter (no iteration): (output, delay, kurtosis).

    The tracking fast path: reuse the previous frame's filter, recompute only the delay
    (``delay`` as in `med`).
    """
    I = _check_image(I)
    W = jnp.asarray(W, I.dtype)
    _length(I, axis, W.shape[0])
    if delay not in DELAYS:
        raise ValueError(f"delay must be one of {', '.join(DELAYS)}, got {delay!r}")
    return _apply(I, W, axis, int(taper), delay, float(ridge_sigma))


@eqx.filter_jit
def _output(I, W, delay, axis, taper):
    pb = med_prepare(I, axis=axis, L=W.shape[0], taper=taper)
    out = _f.shifted_output(W, delay, pb)
    return out.T if axis == 0 else out


def med_output(
    I: Float[Array, "h w"],
    W: Float[Array, " L"],
    delay: Float[Array, ""],
    *,
    axis: int = 0,
    taper: int = DEFAULT_TAPER,
) -> Float[Array, "h w"]:
    """B(i + delay) of eq. (18) for a known filter W (sign included) and a known delay.

    `med_apply` without the delay measurement (no statistics pass, no ridge search): one
    forward and one inverse FFT pass. The pipeline's strided full frame uses it with the
    delay `med` measured on the segments it was run on (`PipelineConfig.med_stride`).
    """
    I = _check_image(I)
    W = jnp.asarray(W, I.dtype)
    _length(I, axis, W.shape[0])
    return _output(I, W, jnp.asarray(delay, I.dtype), axis, int(taper))


def med_objective(
    W: Float[Array, " L"],
    I: Float[Array, "h w"],
    *,
    axis: int = 0,
    form: Form = DEFAULT_FORM,
    taper: int = DEFAULT_TAPER,
) -> Float[Array, ""]:
    """Kurtosis objective of eq. (19) for filter W, by direct convolution (reference path).

    B = full convolution of W with the centred, tapered segments (see the module notes);
    ``form="paper"`` gives (Σ_j k_j − 3)², ``"normalized"`` the mean excess kurtosis
    (M+L−1) k_j − 3 (correction 4). Scale-invariant in W; differentiable.
    """
    I = _check_image(I)
    X = _f.centre_and_taper(stripe_segments(I, axis), taper)
    W = jnp.asarray(W, I.dtype)
    B = jax.vmap(lambda x: jnp.convolve(x, W, mode="full", precision="highest"))(X)
    b = B - jnp.mean(B, axis=-1, keepdims=True)
    U = jnp.sum(b * b, axis=-1)
    F = jnp.sum(b**4, axis=-1)
    ok = U > jnp.finfo(U.dtype).eps * jnp.max(U)
    Us = jnp.where(ok, U, 1.0)
    k = jnp.where(ok, F / (Us * Us), 0.0)
    if form == "paper":
        return (jnp.sum(k) - 3.0) ** 2
    if form == "normalized":
        return jnp.sum(jnp.where(ok, B.shape[-1] * k - 3.0, 0.0)) / jnp.maximum(jnp.sum(ok), 1)
    raise ValueError(f"form must be 'normalized' or 'paper', got {form!r}")
