"""Frequency-domain kernels of the MED fixed point (private; see `cslx.segmentation.med`).

Segments (image columns for the horizontal stripe) are laid out as rows of an (S, M) array
so every FFT runs along the contiguous last axis. Two real segments a, b are packed into one
complex signal z = a + i b: one complex FFT of length n then serves both, and the
half-spectra are recovered with the Hermitian split

    A(f) = (Z(f) + Z*(−f)) / 2,     B(f) = (Z(f) − Z*(−f)) / 2i.

A real filter keeps the packing intact under multiplication, so B = W ∗ X for both
segments comes out of a single inverse FFT as Re + i Im.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np
from jax import lax
from jaxtyping import Array, Complex, Float

from ..reductions import first_argmax


def fft_length(n: int) -> int:
    """Smallest 5-smooth integer (2^a 3^b 5^c) ≥ n: fast FFT sizes (720 for 719)."""
    best = 1 << max(0, math.ceil(math.log2(max(n, 1))))
    p5 = 1
    while p5 < 2 * n:
        p35 = p5
        while p35 < 2 * n:
            m = p35
            while m < n:
                m *= 2
            best = min(best, m)
            p35 *= 3
        p5 *= 5
    return best


def taper_window(m: int, taper: int, dtype) -> Float[Array, " m"]:
    """Raised-cosine ramps of ``taper`` samples at both ends of a segment of length m."""
    i = jnp.arange(m, dtype=dtype)
    if taper <= 0:
        return jnp.ones(m, dtype)
    t = jnp.minimum(i + 1, m - i) / (taper + 1)
    return jnp.where(t < 1, 0.5 - 0.5 * jnp.cos(jnp.pi * jnp.clip(t, 0, 1)), 1.0).astype(dtype)


def centre_and_taper(segments: Float[Array, "s m"], taper: int) -> Float[Array, "s m"]:
    """X = t ⊙ (x − μ_t) with μ_t the t-weighted mean: zero mean and zero at both ends.

    The zero ends remove the step that zero padding would otherwise put at the borders
    (whose derivative is the trivial, perfectly "kurtotic" border-spike solution of MED);
    the weighted mean keeps every segment exactly centred, so the full convolution
    B = W ∗ X is centred too and eq. (22) is the exact stationarity condition.
    """
    t = taper_window(segments.shape[-1], taper, segments.dtype)
    mu = segments @ t / jnp.sum(t)
    return t * (segments - mu[:, None])


class Problem(eqx.Module):
    """Per-frame precomputation for the MED iteration (eqs. (22)–(24) in Fourier form)."""

    X: Float[Array, "s m"]  # the centred, tapered segments (time domain; ridge delay)
    Z: Complex[Array, "p n"]  # FFT of the packed segments x_a + i x_b, length n
    Xa: Complex[Array, "p f"]  # half-spectrum of the even segments
    Xb: Complex[Array, "p f"]  # half-spectrum of the odd segments
    Pa: Float[Array, "p f"]  # |Xa|², summed (weighted) into the autocorrelation of R
    Pb: Float[Array, "p f"]
    m: int = eqx.field(static=True)  # samples per segment
    s: int = eqx.field(static=True)  # real segments (a zero one pads an odd count)
    L: int = eqx.field(static=True)  # filter length
    n: int = eqx.field(static=True)  # FFT length, 5-smooth, ≥ m + L − 1


def prepare(X: Float[Array, "s m"], L: int) -> Problem:
    """FFTs of the centred, tapered segments; done once per frame."""
    s, m = X.shape
    n = fft_length(m + L - 1)
    X0 = X
    if s % 2:
        X = jnp.concatenate([X, jnp.zeros((1, m), X.dtype)])
    Z = jnp.fft.fft(X[0::2] + 1j * X[1::2], n=n, axis=-1)
    Xa, Xb = _split(Z, n)
    return Problem(X0, Z, Xa, Xb, _abs2(Xa), _abs2(Xb), m, s, L, n)


def pairs(pb: Problem, stride: int) -> Problem:
    """The problem of every ``stride``-th packed pair of segments (2j, 2j + 1), j = 0, k, 2k …

    Slices of the spectra `prepare` computed (no FFT); the time-domain segments follow
    (a zero segment pads an odd count, as in `prepare`)."""
    X = pb.X
    if pb.s % 2:
        X = jnp.concatenate([X, jnp.zeros((1, pb.m), X.dtype)])
    X = X.reshape(-1, 2, pb.m)[::stride].reshape(-1, pb.m)
    Z, Xa, Xb, Pa, Pb = (a[::stride] for a in (pb.Z, pb.Xa, pb.Xb, pb.Pa, pb.Pb))
    return Problem(X, Z, Xa, Xb, Pa, Pb, pb.m, X.shape[0], pb.L, pb.n)


def _abs2(z):
    return z.real * z.real + z.imag * z.imag


def _split(Z, n):
    """Half-spectra (f = 0..n/2) of the two real signals packed in Z.

    Z(f) and Z(−f mod n) are read with slices and one reversal, not index arrays: XLA's CPU
    backend runs an index-array gather ≈ per element, and the split is in every MED step.
    """
    zf = Z[:, : n // 2 + 1]
    zr = jnp.conj(jnp.concatenate([Z[:, :1], Z[:, n - n // 2 :][:, ::-1]], axis=1))
    return 0.5 * (zf + zr), -0.5j * (zf - zr)


def _segment_sums(B, L, m, total):
    """Centred output and per-segment energy U (eq. (23)) and 4th power sums.

    ``total``: Σ_i B_i per (packed) segment, the DC bin of B's spectrum: the mean comes
    from it, not from a masked complex sum over B, which XLA's CPU backend ran as a
    materialised select and a tree reduction, ≈ 0.3 ms of a 0.9 ms step on 120×960
    (issue 13; B is zero past m + L − 1 in exact arithmetic, so the sums agree to
    rounding).

    B holds the n ≥ m + L − 1 samples of the circular convolution; only the first m + L − 1
    are the full convolution. They are selected with a mask, not a slice: the centred
    output keeps all n samples, zero past m + L − 1, so the cube of `update` needs no pad
    before its FFT, and the (p, m + L − 1) complex slice, which XLA's CPU backend copied out
    in a kernel of its own, goes (issue 13; the same values to float32 rounding: the sums
    run over n samples, the last n − m − L + 1 of them zero).
    """
    n, mL = B.shape[-1], m + L - 1
    mean = (total / mL)[:, None]
    if n == mL:
        b = B - mean
    else:
        b = jnp.where(jnp.arange(n) < mL, B - mean, 0)
    ba, bb = b.real, b.imag
    ba2, bb2 = ba * ba, bb * bb
    U = jnp.concatenate([jnp.sum(ba2, -1), jnp.sum(bb2, -1)])
    F = jnp.concatenate([jnp.sum(ba2 * ba2, -1), jnp.sum(bb2 * bb2, -1)])
    return ba, bb, U, F


class Stats(eqx.Module):
    """Column statistics of B = W ∗ X for the current filter."""

    ratio_sum: Float[Array, ""]  # Σ_j k_j, k_j = Σ(B−μ)⁴ / U_j²  (eq. (24))
    excess: Float[Array, ""]  # mean sample excess kurtosis over non-constant segments
    w: Float[Array, " s2"]  # R weights k_j / U_j (eq. (22), left)
    v: Float[Array, " s2"]  # b weights 1 / U_j² (eq. (22), right)
    ba: Float[Array, "p n"]  # centred output, zero past the full convolution (m + L − 1)
    bb: Float[Array, "p n"]


#: FFT lengths up to this take a filter's spectrum and the short inverse transforms of the
#: MED step as products with constant DFT matrices (the tracking bands: n = 80, 144).
DFT_MATRIX_MAX = 256


def _dft_matrix(L: int, n: int) -> np.ndarray:
    """(L, 2n) [cos | −sin] of 2πkf/n: W @ it is the real and imaginary part of fft(W, n)."""
    ang = 2 * np.pi * np.outer(np.arange(L), np.arange(n)) / n
    return np.concatenate([np.cos(ang), -np.sin(ang)], axis=1)


def _irdft_head(n: int, L: int) -> np.ndarray:
    """(2(n//2 + 1), L) matrix: [Re G, Im G] @ it is irfft(G, n)[:L] (imaginary parts of the
    DC and Nyquist bins ignored, as `jnp.fft.irfft` does)."""
    f = np.arange(n // 2 + 1)
    a = np.where((f == 0) | (2 * f == n), 1.0, 2.0) / n
    ang = 2 * np.pi * np.outer(f, np.arange(L)) / n
    sin = np.sin(ang)
    sin[(f == 0) | (2 * f == n)] = 0.0
    return np.concatenate([a[:, None] * np.cos(ang), -a[:, None] * sin], axis=0)


def _dot(x, M):
    return jnp.dot(x, jnp.asarray(M, x.dtype), precision=lax.Precision.HIGHEST)


def filter_spectrum(W: Float[Array, " L"], n: int) -> Complex[Array, " n"]:
    """fft(W, n); for n ≤ `DFT_MATRIX_MAX` one product with a constant DFT matrix (an FFT
    library call on one short vector costs more than the product, issue 13)."""
    if n > DFT_MATRIX_MAX:
        return jnp.fft.fft(W, n=n)
    y = _dot(W, _dft_matrix(W.shape[0], n))
    return lax.complex(y[:n], y[n:])


def irfft_head(G: Array, n: int, L: int) -> Float[Array, " L"]:
    """``jnp.fft.irfft(G, n)[:L]`` for one (n//2 + 1,) half-spectrum, real or complex; for
    n ≤ `DFT_MATRIX_MAX` one product with a constant matrix (`filter_spectrum`'s reason)."""
    if n > DFT_MATRIX_MAX:
        return jnp.fft.irfft(G, n=n)[:L]
    M = _irdft_head(n, L)
    if not jnp.iscomplexobj(G):
        return _dot(G, M[: n // 2 + 1])
    return _dot(jnp.concatenate([G.real, G.imag]), M)


def stats(W: Float[Array, " L"], pb: Problem) -> Stats:
    """Output B (one inverse FFT for two segments) and the weights of eq. (22)."""
    S = pb.Z * filter_spectrum(W, pb.n)
    B = jnp.fft.ifft(S, axis=-1)
    ba, bb, U, F = _segment_sums(B, pb.L, pb.m, S[:, 0])
    # Constant segments (zero variance: a padded segment, a black or clipped column) carry
    # no kurtosis; give them zero weight instead of 0/0.
    ok = U > jnp.finfo(U.dtype).eps * jnp.max(U)
    Us = jnp.where(ok, U, 1.0)
    k = jnp.where(ok, F / (Us * Us), 0.0)
    n_ok = jnp.maximum(jnp.sum(ok), 1)
    excess = jnp.sum(jnp.where(ok, (pb.m + pb.L - 1) * k - 3.0, 0.0)) / n_ok
    return Stats(
        jnp.sum(k), excess, jnp.where(ok, k / Us, 0.0), jnp.where(ok, 1 / (Us * Us), 0.0), ba, bb
    )


def weighted_autocorrelation(w: Float[Array, " s2"], pb: Problem) -> Float[Array, " L"]:
    """r(τ) = Σ_j w_j Σ_i X_ij X_{i+τ,j} for the lags τ = 0..L − 1 (n ≥ m + L − 1: no wrap)."""
    p = pb.Pa.shape[0]
    P = w[:p] @ pb.Pa + w[p:] @ pb.Pb
    return irfft_head(P, pb.n, pb.L)


def symmetric_basis(L: int) -> np.ndarray:
    """(L, ⌈L/2⌉) 0/1 matrix P with W = P h: the linear-phase filters W_k = W_{L−1−k}."""
    P = np.zeros((L, (L + 1) // 2))
    for k in range(L):
        P[k, min(k, L - 1 - k)] = 1.0
    return P


def update(
    W: Float[Array, " L"], pb: Problem, loading: float, symmetric: bool = False
) -> tuple[Array, Stats]:
    """One fixed-point step W ← R⁻¹b / ‖R⁻¹b‖ (eqs. (22)–(24), correction 5).

    R_kl = Σ_j (k_j/U_j) Σ_i X_{i−l,j} X_{i−k,j}  (Toeplitz: weighted autocorrelation)
    b_k  = Σ_j U_j⁻² Σ_i (B_ij − μ_j)³ X_{i−k,j}  (weighted cross-correlation)
    Both are sums over segments of correlations, accumulated in the frequency domain and
    brought back with one short inverse FFT each. ``loading`` adds loading·R_00 to the
    diagonal before the solve (`toeplitz_solve`).

    ``symmetric``: the same stationarity condition restricted to linear-phase filters
    W = P h (`symmetric_basis`): the gradient of eq. (19) projected on them vanishes when
    Pᵀ R P h ∝ Pᵀ b, so h ← (PᵀRP)⁻¹ Pᵀb and W = P h, normalised.
    """
    st = stats(W, pb)
    L, n = pb.L, pb.n
    # Two real FFTs of the cubes, not one packed complex FFT and its Hermitian split: the
    # split's reversal and concatenation cost more than the FFT saves (issue 13: 160×720 and
    # 120×960 pairs, 0.26–0.29 → 0.16 ms on this CPU).
    Ca = jnp.fft.rfft(st.ba * st.ba * st.ba, n=n, axis=-1)
    Cb = jnp.fft.rfft(st.bb * st.bb * st.bb, n=n, axis=-1)
    p = pb.Xa.shape[0]
    G = st.v[:p] @ (jnp.conj(pb.Xa) * Ca) + st.v[p:] @ (jnp.conj(pb.Xb) * Cb)
    bvec = irfft_head(G, n, L)
    r = weighted_autocorrelation(st.w, pb)
    r = r.at[0].multiply(1 + loading)  # R + loading·R_00·I: the same Toeplitz form
    if symmetric:
        P = symmetric_basis(L)
        if P.shape[1] <= SMALL_SOLVE:
            # PᵀR P as one product of r with a constant (its entries are sums of r's lags)
            # and the system solved by unrolled elimination: no gather, no library calls
            A = _dot(r, _symmetric_gram(L)).reshape(P.shape[1], P.shape[1])
            x = _dot(spd_solve(A, _dot(bvec, P)), P.T)
        else:
            Pj = jnp.asarray(P, r.dtype)
            h = jsl.cho_solve(jsl.cho_factor(Pj.T @ toeplitz(r) @ Pj, lower=True), Pj.T @ bvec)
            x = Pj @ h
    else:
        x = toeplitz_solve(r, bvec)
    return x / jnp.linalg.norm(x), st


#: Linear-phase systems of up to this many unknowns are solved by `spd_solve`.
SMALL_SOLVE = 16


def _symmetric_gram(L: int) -> np.ndarray:
    """(L, h²) constant G with r @ G = vec(Pᵀ R P), R_kl = r(|k − l|), P `symmetric_basis`."""
    P = symmetric_basis(L)
    h = P.shape[1]
    lag = np.abs(np.arange(L)[:, None] - np.arange(L)[None, :])
    G = np.zeros((L, h * h))
    for tau in range(L):
        G[tau] = (P.T @ (lag == tau).astype(float) @ P).ravel()
    return G


def spd_solve(A: Float[Array, "n n"], b: Float[Array, " n"]) -> Float[Array, " n"]:
    """A⁻¹b for a small symmetric positive definite A: Gaussian elimination without pivoting
    (stable for SPD matrices) and back substitution, two `lax.fori_loop`s of whole-row
    updates (with `cslx.environment.small_loops` XLA's CPU backend runs each as one
    function). The 8×8 linear-phase system of the tracking bands took a Cholesky
    factorisation and two triangular solves (three library calls, ≈ 15–30 µs a band on this
    CPU, issue 13); the same solution to rounding."""
    n = A.shape[0]
    idx = jnp.arange(n)

    def eliminate(k, Ab):
        A, b = Ab
        f = jnp.where(idx > k, A[:, k] / A[k, k], 0.0)
        return A - f[:, None] * A[k][None, :], b - f * b[k]

    def substitute(j, x):  # x is zero at and below k: the sum runs over the solved entries
        k = n - 1 - j
        return jnp.where(idx == k, (b[k] - jnp.sum(A[k] * x)) / A[k, k], x)

    A, b = lax.fori_loop(0, n, eliminate, (A, b))
    return lax.fori_loop(0, n, substitute, jnp.zeros_like(b))


def toeplitz(r: Float[Array, " L"]) -> Float[Array, "L L"]:
    """The symmetric Toeplitz matrix R_kl = r(|k − l|)."""
    L = r.shape[0]
    return r[jnp.abs(jnp.arange(L)[:, None] - jnp.arange(L)[None, :])]


def toeplitz_solve(r: Float[Array, " L"], b: Float[Array, " L"]) -> Float[Array, " L"]:
    """R⁻¹ b for the positive definite symmetric Toeplitz R_kl = r(|k − l|) (eq. (22)).

    On the CPU by the Levinson recursion (`levinson`, O(L²)); elsewhere (GPU) by a Cholesky
    factorisation of R (O(L³) but one library call; a loop of L small steps would be L
    kernel launches there). Issue 13, this 2-core CPU, float32, one solve: L = 240
    0.23 → 0.07 ms, L = 320 0.45 → 0.12 ms (p10 of 200 calls, load 5), the same relative
    error against SciPy's float64 `solve_toeplitz` (2e-3 for both on a system of
    condition 7e5).
    """
    return lax.platform_dependent(
        r,
        b,
        cpu=levinson,
        default=lambda r, b: jsl.cho_solve(jsl.cho_factor(toeplitz(r), lower=True), b),
    )


def levinson(r: Float[Array, " L"], b: Float[Array, " L"]) -> Float[Array, " L"]:
    """Levinson's recursion for R x = b, R_kl = r(|k − l|) positive definite.

    Golub & Van Loan, Matrix Computations, Algorithm 4.7.2 (on R / r(0), unit diagonal):
    the solution x and the Yule–Walker vector y of the leading k×k system grow one order a
    step, each from inner products with r(1..k) reversed, O(L) work per step. The loop
    touches only a few L-vectors, so with `cslx.environment.small_loops` XLA's CPU backend
    runs it as one function.
    """
    L = r.shape[0]
    t, b = r / r[0], b / r[0]
    i = jnp.arange(L)
    zero = jnp.zeros(L, r.dtype)
    t_rev = jnp.concatenate([t[::-1], zero])  # t(k − j) = t_rev[L − 1 − k + j]
    t_next = jnp.concatenate([t[1:], t[-1:]])  # t(k + 1); the last entry is unused

    def step(k, carry):
        x, y, beta, alpha = carry
        beta = (1 - alpha * alpha) * beta
        tk = jnp.where(i < k, lax.dynamic_slice(t_rev, (L - 1 - k,), (L,)), 0)  # t(k − j)
        yk = lax.dynamic_slice(jnp.concatenate([y[::-1], zero]), (L - k,), (L,))  # y(k−1−j)
        mu = (b[k] - tk @ x) / beta
        alpha = (-t_next[k] - tk @ y) / beta
        x = jnp.where(i == k, mu, x + mu * yk)
        y = jnp.where(i == k, alpha, y + alpha * yk)
        return x, y, beta, alpha

    if L == 1:
        return b
    x0, y0 = zero.at[0].set(b[0]), zero.at[0].set(-t[1])
    x, *_ = lax.fori_loop(1, L, step, (x0, y0, jnp.ones((), r.dtype), -t[1]))
    return x


def centre_sign(W: Float[Array, " L"], w: Float[Array, " s2"], pb: Problem):
    """Sign of a linear-phase filter: that of the output/input correlation at its centre.

    A symmetric filter delays every frequency by (L − 1)/2 exactly; the sign is chosen so
    that c((L−1)/2) = Σ_j w_j Σ_i B_{i+(L−1)/2, j} X_ij > 0 (the stripe stays bright).
    The correlation is c(t) = Σ_k W_k r(t − k) with r the weighted autocorrelation, even in
    its lag: at the centre it is W · (r(|(L−1)/2 − k|) + r(|L/2 − k|)), taken from the r of
    `update` (the same operations on the same weights, computed once), not through an FFT
    pair (issue 13).
    """
    L = pb.L
    r = weighted_autocorrelation(w, pb)
    k = np.arange(L)
    Q = np.zeros((L, L))
    for t in ((L - 1) // 2, L // 2):
        Q[k, np.abs(t - k)] += 1.0
    mid = jnp.dot(W, _dot(r, Q.T), precision=lax.Precision.HIGHEST)
    return jnp.where(mid < 0, -1.0, 1.0).astype(W.dtype)


def peak_delay(W: Float[Array, " L"], w: Float[Array, " s2"], pb: Problem):
    """Sub-pixel delay and sign of the filter from the cross-correlation of B with X.

    c(τ) = Σ_j w_j Σ_i B_{i+τ,j} X_ij = Σ_k W_k r(τ − k), evaluated on its band-limited
    (trigonometric) interpolant: the integer peak of |c| over τ ∈ [0, L), then Newton steps
    on c'(τ) = 0. For a filter that is a pure (fractional) delay d, c is the symmetric
    autocorrelation centred at d, so its interpolant peaks exactly at d (no parabola bias).
    """
    n, L = pb.n, pb.L
    p = pb.Pa.shape[0]
    P = w[:p] @ pb.Pa + w[p:] @ pb.Pb
    C = jnp.fft.rfft(W, n=n) * P
    c = jnp.fft.irfft(C, n=n)
    # Lags −L+1..L−1 are possible for the correlation, but a causal filter delays: τ ≥ 0.
    k = jnp.argmax(jnp.abs(c[:L]))
    sign = jnp.where(c[k] < 0, -1.0, 1.0).astype(W.dtype)
    f = jnp.arange(n // 2 + 1, dtype=W.dtype)
    omega = 2 * jnp.pi * f / n
    a = jnp.where((f == 0) | (2 * f == n), 1.0, 2.0) / n
    Cs = C * sign

    def derivs(t):
        e = Cs * jnp.exp(1j * omega * t)
        d1 = jnp.sum(a * (1j * omega * e).real)
        d2 = jnp.sum(a * (-(omega**2) * e).real)
        return d1, d2

    def newton(t, _):
        d1, d2 = derivs(t)
        step = jnp.where(d2 < 0, -d1 / jnp.where(d2 < 0, d2, -1.0), 0.0)
        return t + jnp.clip(step, -0.5, 0.5), None

    t0 = k.astype(W.dtype)
    t, _ = jax.lax.scan(newton, t0, None, length=4)
    t = jnp.clip(t, t0 - 1, t0 + 1)
    return t, sign


def shifted_output(W: Float[Array, " L"], delay, pb: Problem) -> Float[Array, "s m"]:
    """B(i + delay) for i = 0..m−1: the filter output moved back onto the input rows.

    The shift is applied in the Fourier domain (e^{iωd}, Nyquist bin made real so the
    shift filter stays real and the two-segment packing stays exact). A Python number
    ``delay`` (the centre (L − 1)/2 of a linear-phase filter) gives a constant phase,
    computed here in NumPy: XLA's CPU backend fuses a traced phase's sine and cosine into
    the (p, n) product and evaluates them for every segment pair (the 240×144 product of
    the tracking band of columns was 2.7 % of a tracking frame's kernel time, issue 13;
    `optimization_barrier` does not stop it, the CPU backend drops barriers first). MED on
    both tracking bands (2 steps, linear phase): 4.97 → 3.98 ms, 200 calls interleaved
    between two processes, load 7.4–8.3; outputs within 2e-6 of their largest value.
    """
    n = pb.n
    if isinstance(delay, (int, float)):
        f = np.fft.fftfreq(n)
        ph = np.exp(2j * np.pi * f * delay)
        if n % 2 == 0:
            ph[n // 2] = np.cos(np.pi * delay)
        phase = jnp.asarray(ph.astype(np.complex64 if W.dtype == jnp.float32 else np.complex128))
        H = filter_spectrum(W, n) * phase
    else:
        fs = jnp.fft.fftfreq(n).astype(W.dtype)
        phase = jnp.exp(2j * jnp.pi * fs * delay)
        if n % 2 == 0:
            phase = phase.at[n // 2].set(jnp.cos(jnp.pi * delay))
        # The shifted filter's spectrum, recomputed through a (length-n) FFT pair: an FFT's
        # operand is materialised, so the sine and cosine are evaluated n times, not p·n.
        H = jnp.fft.fft(jnp.fft.ifft(filter_spectrum(W, n) * phase))
    B = jnp.fft.ifft(pb.Z * H, axis=-1)[:, : pb.m]
    out = jnp.stack([B.real, B.imag], axis=1).reshape(-1, pb.m)
    return out[: pb.s]


def shift_matrix(W: Float[Array, " L"], delay: float, m: int, n: int) -> Float[Array, "m m"]:
    """`shifted_output` as a matrix: B(i + delay) = Σ_j M_ij X_j for a segment X of m samples.

    The Fourier shift by a static ``delay`` of the length-n circular convolution W ∗ X is a
    circulant operator; its first m rows and columns are M_ij = g((i − j) mod n), g = W ⊛ s
    with s the shift's impulse response (NumPy, static; real, the Nyquist bin being made
    real as in `shifted_output`). g at the 2m − 1 lags i − j is one small product with a
    constant matrix, and the Toeplitz M is laid out from it by reshaping a tiled vector (no
    gather). Filtering the band by this one matrix product replaces the band's forward and
    inverse FFTs (issue 13; `cslx.segmentation.med._lagged`).
    """
    f = np.fft.fftfreq(n)
    ph = np.exp(2j * np.pi * f * delay)
    if n % 2 == 0:
        ph[n // 2] = np.cos(np.pi * delay)
    s = np.fft.ifft(ph).real
    lags = np.arange(m - 1, -m, -1)  # v[q] = g(m − 1 − q): the lags i − j, reversed
    S = s[(lags[:, None] - np.arange(W.shape[0])[None, :]) % n]
    v = jnp.dot(jnp.asarray(S, W.dtype), W, precision=lax.Precision.HIGHEST)
    # row i of this (m, 2m − 2) view of v tiled starts at v[m − 1 − i]: M_ij = v[m − 1 − i + j]
    p = 2 * m - 1
    return jnp.tile(v, m + 1)[m - 1 : m - 1 + m * (p - 1)].reshape(m, p - 1)[:, :m]


def centre_output(st: Stats, sign, pb: Problem) -> Float[Array, "s m"]:
    """`shifted_output` of a linear-phase filter of odd length L, from B itself (no FFT).

    Its delay (L − 1)/2 is a whole number of samples, so B(i + delay) is a slice of the full
    convolution B = W ∗ X that `stats` already computed for the filter (n ≥ m + L − 1: no
    wrap-around). ``st.ba``/``st.bb`` are B less its segment means, which are zero because
    the tapered segments X sum to zero (`centre_and_taper`); ``sign`` is the filter's
    sign (`centre_sign`). Equal to `shifted_output` up to float rounding.
    """
    if pb.L % 2 == 0:
        raise ValueError(f"the delay of an even-length filter (L = {pb.L}) is not a whole sample")
    d = (pb.L - 1) // 2
    B = jnp.stack([st.ba, st.bb], axis=1).reshape(-1, st.ba.shape[-1])
    return sign * B[: pb.s, d : d + pb.m]


def ridge_positions(Y: Float[Array, "s k"], sigma: float):
    """Sub-pixel ridge of each row of Y at scale σ: (position, ok).

    Start at the brightest sample k, move once to the nearest sample of the
    Gaussian-smoothed ridge and take Steger's 1-D Newton offset t = −s'(k)/s''(k) there, with
    s the row smoothed by a Gaussian of scale σ, truncated at 4σ (the 1-D form of the
    detector the pipeline runs on the MED output). s' and s'' are needed at two samples a
    row only, so they are evaluated there, from the 2h + 1 samples around each (h the
    truncation; zero outside the row), with folded taps, not filtered over the whole row,
    and k is found by `first_argmax`. Issue 13, the ridge delay of the cold full frame's
    strided MED (p10 of 150 calls, beyond the statistics pass): 160 columns of 719 samples
    1.61 → 0.20 ms, 240 rows of 959 samples 3.26 → 0.26 ms; the same positions to float
    rounding. ok: a maximum (s'' < 0) within 0.6 sample (Steger's offset bound in cslx).
    """
    n = Y.shape[-1]
    h = min(int(4.0 * sigma + 0.5), n - 1)
    o = np.arange(h + 1, dtype=np.float64)
    g = np.exp(-0.5 * (o / sigma) ** 2)
    g /= g[0] + 2 * g[1:].sum()
    g1 = -o / sigma**2 * g  # g'(o); odd
    g2 = (o**2 / sigma**4 - 1 / sigma**2) * g  # g''(o); even
    offsets = jnp.arange(-h, h + 1)

    def at(k):
        # s'(k) = Σ_o y(k − o) g'(o) = Σ_{o>0} g'(o) (y(k − o) − y(k + o)); s'' alike, even.
        idx = k[:, None] + offsets
        inside = (idx >= 0) & (idx < n)
        y = jnp.where(inside, jnp.take_along_axis(Y, jnp.clip(idx, 0, n - 1), axis=-1), 0.0)
        t1 = jnp.zeros_like(y[:, h])
        t2 = float(g2[0]) * y[:, h]
        for j in range(1, h + 1):
            before, after = y[:, h - j], y[:, h + j]
            t1 = t1 + float(g1[j]) * (before - after)
            t2 = t2 + float(g2[j]) * (before + after)
        return -t1 / jnp.where(t2 < 0, t2, -1.0), t2

    k, _ = first_argmax(Y)
    t, _ = at(k)
    k = jnp.clip(k + jnp.clip(jnp.round(t), -h, h).astype(k.dtype), 0, n - 1)
    t, t2 = at(k)
    return k.astype(Y.dtype) + t, (t2 < 0) & (jnp.abs(t) <= 0.6)


#: Segments (evenly spaced) whose ridge displacement `ridge_delay` takes the median of.
RIDGE_SEGMENTS = 128


def ridge_delay(W, st: Stats, sign, d0, pb: Problem, sigma: float, window: float = 3.0):
    """Delay of the filter as the displacement of the stripe's ridge from input to output.

    The cross-correlation peak `peak_delay` is the delay of a linear-phase (symmetric)
    filter. MED's filter is not constrained to be symmetric, and on short segments (the
    tracking bands) it converges to a one-sided, edge-enhancing filter whose ridge, seen at
    the detector's scale σ, sits 1–2 px away from the correlation peak (measured on rendered
    frames): the band bias. Here the ridge of every segment is located at scale σ in the
    input X and in the output B = W ∗ X (`ridge_positions`), and the delay is the median of
    the displacements over segments where both are ridges and the displacement lies within
    ``window`` px of the correlation estimate ``d0`` (segments without a stripe drop out),
    over at most `RIDGE_SEGMENTS` evenly spaced segments.
    Falls back to ``d0`` when no segment qualifies.
    """
    del W
    # At most RIDGE_SEGMENTS evenly spaced segments: the median needs no more, and the
    # ridge search costs as much as a Steger pass on the band when run on all of them.
    step = max(1, pb.s // RIDGE_SEGMENTS)
    B = jnp.stack([st.ba, st.bb], axis=1).reshape(-1, st.ba.shape[-1])[: pb.s : step]
    B = B[:, : pb.m + pb.L - 1]  # the full convolution (`_segment_sums` keeps n samples)
    pX, okX = ridge_positions(pb.X[::step], sigma)
    pB, okB = ridge_positions(sign * B, sigma)
    diff = pB - pX
    good = okX & okB & (jnp.abs(diff - d0) <= window)
    d = jnp.nanmedian(jnp.where(good, diff, jnp.nan))
    return jnp.where(jnp.any(good), d, d0).astype(d0.dtype)
