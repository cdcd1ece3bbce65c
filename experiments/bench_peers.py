"""Peers of the cslx segmentation stages, for `experiments.bench_speed`: the same work done
with NumPy/SciPy, OpenCV, scikit-image and the PyPI package `ridge-detection`."""

from __future__ import annotations

import numpy as np

SIGMA = 2.0


def numpy_med_prepare(X: np.ndarray, L: int):
    """Per-frame part of the plain NumPy MED: FFTs of the (S, M) centred, tapered segments."""
    import scipy.fft

    n = scipy.fft.next_fast_len(X.shape[1] + L - 1)
    return dict(X=X, L=L, n=n, Xf=np.fft.rfft(X, n), P=None)


def numpy_med_update(W: np.ndarray, pb: dict, loading: float) -> np.ndarray:
    """One fixed-point step of eqs. (22)–(24) (docs/corrections.md, 5), plain NumPy/SciPy.

    B = W ∗ X per segment (full convolution by FFT), U_j, k_j from the centred output,
    R = Toeplitz(Σ_j (k_j/U_j) autocorr(X_j)), b_k = Σ_j U_j⁻² Σ_i b_ij³ X_{i−k,j},
    W ← R⁻¹ b / ‖R⁻¹ b‖ with `scipy.linalg.solve_toeplitz` (Levinson).
    """
    import scipy.linalg

    L, n, Xf = pb["L"], pb["n"], pb["Xf"]
    m = pb["X"].shape[1]
    B = np.fft.irfft(Xf * np.fft.rfft(W, n), n)[:, : m + L - 1]
    b = B - B.mean(axis=1, keepdims=True)
    b2 = b * b
    U = b2.sum(axis=1)
    ok = U > np.finfo(U.dtype).eps * U.max()
    Us = np.where(ok, U, 1.0)
    k = np.where(ok, (b2 * b2).sum(axis=1) / Us**2, 0.0)
    w = np.where(ok, k / Us, 0.0)
    v = np.where(ok, 1.0 / Us**2, 0.0)
    r = np.fft.irfft(w @ (Xf.real**2 + Xf.imag**2), n)[:L]
    g = np.fft.irfft(v @ (np.conj(Xf) * np.fft.rfft(b2 * b, n)), n)[:L]
    r = r.copy()
    r[0] += loading * r[0]
    x = scipy.linalg.solve_toeplitz(r, g)
    return x / np.linalg.norm(x)


def gaussian_kernels(sigma: float):
    """Correlation kernels (for cv2) of the Gaussian and its 1st/2nd derivatives, truncate 4σ."""
    r = int(4.0 * sigma + 0.5)
    x = np.arange(-r, r + 1, dtype=np.float64)
    phi = np.exp(-0.5 * x**2 / sigma**2)
    phi /= phi.sum()
    g = [phi, -x / sigma**2 * phi, (x**2 / sigma**4 - 1 / sigma**2) * phi]
    # scipy/cslx convolve (out[i] = Σ g(k) x[i − k]); cv2 correlates: reverse the taps.
    return [k[::-1].astype(np.float32).copy() for k in g]


def opencv_steger(img: np.ndarray, kernels, *, threshold=0.1, snr=5.0, max_offset=0.6):
    """Steger per column with cv2.sepFilter2D derivatives and a NumPy selection (a peer).

    Same closed-form Hessian eigen-decomposition, offset and acceptance as `steger`;
    per column the strongest accepted point (argmax), moved to the column along the line.
    """
    import cv2

    g0, g1, g2 = kernels
    border = cv2.BORDER_REFLECT  # d c b a | a b c d, scipy's "reflect"

    def sep(kx, ky):
        return cv2.sepFilter2D(img, cv2.CV_32F, kx, ky, borderType=border)

    rv, ru = sep(g0, g1), sep(g1, g0)
    rvv, ruu, ruv = sep(g0, g2), sep(g2, g0), sep(g1, g1)
    half = 0.5 * (rvv - ruu)
    s = np.sqrt(half**2 + ruv**2)
    lam = 0.5 * (rvv + ruu) - s
    first = half >= 0
    ev = np.where(first, ruv, lam - ruu)
    eu = np.where(first, lam - rvv, ruv)
    norm = np.sqrt(ev**2 + eu**2)
    norm = np.where(norm > 0, norm, 1.0)
    nv, nu = ev / norm, eu / norm
    neg = lam < 0
    t = np.where(neg, -(nv * rv + nu * ru) / np.where(neg, lam, -1.0), 0.0)
    strength = -lam
    steep = np.abs(nv) >= 0.5  # 60° from the column direction, as cslx
    geometric = neg & (np.abs(t * nv) <= max_offset) & (np.abs(t * nu) <= max_offset)
    strongest = np.max(np.where(geometric & steep, strength, 0.0))
    accept = (
        geometric
        & steep
        & (strength >= threshold * strongest)
        & (strength >= snr * np.mean(np.abs(lam)))
    )
    score = np.where(accept, strength, 0.0)
    row = np.argmax(score, axis=0)
    cols = np.arange(img.shape[1])
    valid = score[row, cols] > 0
    pos = row + t[row, cols] / np.where(steep[row, cols], nv[row, cols], 1.0)
    return np.where(valid, pos, np.nan), valid


def skimage_hessian(img: np.ndarray):
    """scikit-image's Hessian ridge measures: Gaussian-derivative Hessian + eigenvalues."""
    from skimage.feature import hessian_matrix, hessian_matrix_eigvals

    H = hessian_matrix(img, sigma=SIGMA, order="rc", use_gaussian_derivatives=True)
    return hessian_matrix_eigvals(H)


def ridge_detection_peer(mono_u8: np.ndarray):
    """The PyPI `ridge-detection` package on one frame (a PIL image: it reads a NumPy
    array's shape as (width, height))."""
    from PIL import Image
    from ridge_detection.lineDetector import LineDetector

    params = {
        "path_to_file": "",
        "mandatory_parameters": {
            "Sigma": SIGMA,
            "Lower_Threshold": 1.0,
            "Upper_Threshold": 5.0,
            "Maximum_Line_Length": 0,
            "Minimum_Line_Length": 0,
            "Darkline": "LIGHT",
            "Overlap_resolution": "NONE",
        },
        "optional_parameters": {"Line_width": 6.0, "High_contrast": 200, "Low_contrast": 40},
        "further_options": {
            "Correct_position": True,
            "Estimate_width": False,
            "doExtendLine": True,
            "Show_junction_points": False,
            "Show_IDs": False,
            "Display_results": False,
            "Preview": False,
            "Make_Binary": False,
            "save_on_disk": False,
        },
    }
    detector = LineDetector(params=params)
    return detector.detectLines(Image.fromarray(mono_u8))
