"""Beyond the paper: learn the pipeline's continuous parameters by gradient descent.

Every stage of cslx is JAX, so the 3-D error of the triangulated stripe is a differentiable
function of the pipeline's settings. This script tunes

- the colour weights w of eq. (8) (on the unit sphere: w / ‖w‖ is used),
- Steger's scale σ (continuous here; the library's detector takes it as a static float),
- MED's diagonal loading of R (eq. (22), `cslx.segmentation.med.med`'s ``loading``, as log10),

by minimising a robust (Huber, δ = 1 mm) 3-D error against rendered ground truth on
TRAINING scenes, with `jax.grad` driving optimistix's BFGS one step at a time (so that the
loss curve can be recorded). It then evaluates the ordinary, hard pipeline
(`cslx.segmentation.extract(..., "med")`: converged MED, Steger's thresholds, no softness) with
the tuned settings on HELD-OUT seeds, including nuisance kinds and a scene kind never seen in
training, against the paper's fixed settings (R−G, σ = 2 px, default MED).

The differentiable surrogate (`soft_centres`, `surrogate_loss`) differs from the hard
pipeline in three ways, each needed for a useful gradient:

1. MED is unrolled for a fixed number of fixed-point steps of eqs. (22)–(24)
   (`med.med_update`) from Table 2's flat start instead of iterated to the tolerance;
   the gradient flows through every Cholesky solve and the delay estimate.
2. Steger's Gaussian derivatives use taps computed from a traced σ on a fixed support
   (4 σ_max), not the static scipy-exact kernel.
3. The per-column centre is a softmax-weighted average of Steger's sub-pixel positions
   (weights exp(−λ / (τ max(−λ))) over the column), not the hard strongest point with
   thresholds: the loss is then smooth in every parameter. With τ = 0.03 the soft centre
   sits within hundredths of a pixel of the hard one on a clean stripe.

The MED filter length L is not differentiable; it is left at the paper's 50 %.

Run: `python -m experiments.tune_differentiable` (≈ 10–15 min on 2 cores) or `--quick`.
Writes `results/tune_differentiable.{csv,md,png}` with the provenance of the run.
"""

from __future__ import annotations

import argparse
import math
import os
import pathlib
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results"

#: The paper's fixed settings: R−G, Steger σ = 2 px (`cslx.segmentation.DEFAULT_SIGMA`), MED's
#: default float32 loading 1e-5.
PAPER = dict(weights=(1.0, -1.0, 0.0), sigma=2.0, loading=1e-5)
SIGMA_RANGE = (0.7, 4.5)
#: The weights enter as θ_w with ‖θ_w‖ = 1 / W_SCALE (only the direction is used), so BFGS's
#: first (identity-Hessian) step changes the direction by ≈ W_SCALE² × the gradient: the
#: loss is rugged in w (MED switches basins, see the results), so w must start with small
#: steps.
W_SCALE = 0.1

CONFIG = dict(
    train_kinds=("straight",),
    train_nuisances=("sunny", "shadow"),
    train_seed=100,
    train_frames=3,  # per (kind, nuisance)
    test_kinds=("straight", "cross"),
    test_nuisances=("clean", "sunny", "shadow", "glare"),
    test_seed=200,
    test_frames=4,  # per (kind, nuisance)
    stripes=("h", "v"),
    med_steps=6,  # unrolled fixed-point steps in the surrogate
    tau=0.03,  # softmax temperature, relative to the column's strongest ridge
    huber_mm=1.0,
    bfgs_steps=20,
    rtol=1e-4,
    atol=1e-4,
)
QUICK = dict(
    train_frames=1,
    test_kinds=("straight",),
    test_nuisances=("sunny", "glare"),
    test_frames=1,
    bfgs_steps=3,
)


# ----------------------------------------------------------------------------- surrogate


def _gauss_taps(sigma, order: int, radius: int):
    """Gaussian (derivative) taps g(x), x = −radius..radius, differentiable in σ.

    Same formula as `cslx.segmentation.steger` (sampled, normalised Gaussian times the derivative
    polynomial) on a fixed support, so that σ can be traced.
    """
    import jax.numpy as jnp

    x = jnp.arange(-radius, radius + 1, dtype=sigma.dtype)
    phi = jnp.exp(-0.5 * x**2 / sigma**2)
    phi = phi / jnp.sum(phi)
    poly = {0: jnp.ones_like(x), 1: -x / sigma**2, 2: x**2 / sigma**4 - 1 / sigma**2}[order]
    return poly * phi


def _filter_axis(x, taps, axis: int, odd: bool):
    """out[i] = Σ_k g(k) x[i − k] with the reflect boundary (as `scipy.ndimage`)."""
    import jax.numpy as jnp
    from jax import lax

    r = (taps.shape[0] - 1) // 2
    n = x.shape[axis]
    pad = [(0, 0)] * x.ndim
    pad[axis] = (r, r)
    xp = jnp.pad(x, pad, mode="symmetric")

    def shifted(k):
        return lax.slice_in_dim(xp, r + k, r + k + n, axis=axis)

    # Taps are symmetric (orders 0, 2) or antisymmetric (order 1): fold them.
    out = taps[r] * shifted(0)
    sign = -1.0 if odd else 1.0
    for k in range(1, r + 1):
        out = out + taps[r + k] * (shifted(-k) + sign * shifted(k))
    return out


def soft_centres(image, sigma, axis: int, tau: float, radius: int):
    """Softmax-weighted Steger centre per column (axis 0) or row (axis 1), differentiable.

    Args:
        image: (H, W) float image, bright stripe.
        sigma: traced scalar Steger scale, px.
        axis: 0 — one centre per column (row coordinate v); 1 — per row (column u).
        tau: temperature relative to each column's largest ridge strength −λ.
        radius: fixed support of the Gaussian taps (≥ 4 σ).

    Returns:
        (N,) sub-pixel positions: Σ_i p_i (i + t_i / n_i) with p = softmax(−λ / (τ max −λ))
        over ridge pixels (λ < 0, normal within 60° of the search axis), Steger's Taylor
        offset t (eq. (17) of Steger 1998) clipped to ±1 px.
    """
    import jax
    import jax.numpy as jnp

    g = {o: _gauss_taps(sigma, o, radius) for o in (0, 1, 2)}
    a0, a1, a2 = (_filter_axis(image, g[o], 0, o == 1) for o in (0, 1, 2))
    ru, ruu = _filter_axis(a0, g[1], 1, True), _filter_axis(a0, g[2], 1, False)
    rv, ruv = _filter_axis(a1, g[0], 1, False), _filter_axis(a1, g[1], 1, True)
    rvv = _filter_axis(a2, g[0], 1, False)
    half = 0.5 * (rvv - ruu)
    q = half**2 + ruv**2
    s = jnp.sqrt(q + 1e-12 * (jnp.max(q) + 1e-30))
    lam = 0.5 * (rvv + ruu) - s
    first = half >= 0
    ev = jnp.where(first, ruv, lam - ruu)
    eu = jnp.where(first, lam - rvv, ruv)
    nrm = jnp.sqrt(ev**2 + eu**2 + 1e-30)
    nv, nu = ev / nrm, eu / nrm
    n_along = nv if axis == 0 else nu
    ok = (lam < 0) & (jnp.abs(n_along) >= 0.5)
    safe_lam = jnp.where(lam < 0, lam, -1.0)
    t = -(nv * rv + nu * ru) / safe_lam
    offset = jnp.clip(t / jnp.where(ok, n_along, 1.0), -1.0, 1.0)
    strength = jnp.where(ok, -lam, 0.0)
    top = jnp.max(strength, axis=axis, keepdims=True)
    logits = jnp.where(ok, strength / (tau * jnp.maximum(top, 1e-12)), -1e9)
    p = jax.nn.softmax(logits, axis=axis)
    idx = jnp.arange(image.shape[axis], dtype=image.dtype)
    idx = idx[:, None] if axis == 0 else idx[None, :]
    return jnp.sum(p * (idx + offset), axis=axis)


def unpack(theta):
    """(w unit (3,), σ px, loading) from the optimiser's vector (θ_w (3), z_σ, log10 loading)."""
    import jax
    import jax.numpy as jnp

    w = theta[:3] / jnp.linalg.norm(theta[:3])
    lo, hi = SIGMA_RANGE
    sigma = lo + (hi - lo) * jax.nn.sigmoid(theta[3])
    return w, sigma, 10.0 ** theta[4]


def pack(weights, sigma: float, loading: float) -> np.ndarray:
    lo, hi = SIGMA_RANGE
    u = (sigma - lo) / (hi - lo)
    w = np.asarray(weights, float)
    w = w / np.linalg.norm(w) / W_SCALE
    return np.array([*w, math.log(u / (1 - u)), math.log10(loading)])


def _stripe_loss(I, gt_xyz, sensor, theta, axis: int, cfg):
    """Huber 3-D error (mm) of one stripe of one frame, mean over ground-truth columns/rows."""
    import jax.numpy as jnp

    from cslx.segmentation.med import initial_filter, med_apply, med_prepare, med_update
    from cslx.sensor import triangulate

    _, sigma, loading = unpack(theta)
    L = I.shape[axis] // 2
    pb = med_prepare(I, axis=axis, L=L)
    W = initial_filter("flat", L, I.dtype)
    for _ in range(cfg["med_steps"]):
        W, _, _ = med_update(W, pb, loading)
    B, _, _ = med_apply(I, W, axis=axis)
    # Taps cover 4 σ_max; tests pass a shorter support (smaller graph, σ stays ≈ 2).
    radius = cfg.get("taps_radius", int(math.ceil(4 * SIGMA_RANGE[1])))
    pos = soft_centres(B, sigma, axis, cfg["tau"], radius)
    index = jnp.arange(pos.shape[0], dtype=pos.dtype)
    uv = jnp.stack([index, pos] if axis == 0 else [pos, index], axis=-1)
    # A crop's pixel (0, 0) is the frame's (u0, v0) (tests use crops).
    uv = uv + jnp.asarray(cfg.get("origin", (0.0, 0.0)), pos.dtype)
    has_gt = jnp.all(jnp.isfinite(gt_xyz), axis=-1)
    xyz = triangulate(sensor, uv, axis)
    d2 = jnp.sum((xyz - jnp.where(has_gt[:, None], gt_xyz, 0.0)) ** 2, axis=-1)
    err = jnp.sqrt(jnp.where(has_gt, d2, 1.0) + 1e-12)
    delta = cfg["huber_mm"]
    hub = jnp.where(err <= delta, 0.5 * err**2 / delta, err - 0.5 * delta)
    hub = jnp.where(has_gt & jnp.isfinite(hub), hub, 0.0)
    return jnp.sum(hub) / jnp.maximum(jnp.sum(has_gt), 1)


def surrogate_loss(theta, images, gts, sensor, cfg):
    """Mean over frames and stripes of the Huber 3-D error of the soft pipeline (mm).

    Frames go through `lax.map` (one compiled frame body, a sequential loop on the CPU).
    """
    import jax
    import jax.numpy as jnp

    from cslx.segmentation.colour import monochrome

    w, _, _ = unpack(theta)

    def one(frame):
        rgb, gh, gv = frame
        I = monochrome(rgb, w)
        parts = []
        if "h" in cfg["stripes"]:
            parts.append(_stripe_loss(I, gh, sensor, theta, 0, cfg))
        if "v" in cfg["stripes"]:
            parts.append(_stripe_loss(I, gv, sensor, theta, 1, cfg))
        return jnp.mean(jnp.stack(parts))

    return jnp.mean(jax.lax.map(one, (images, gts["h_xyz"], gts["v_xyz"])))


def train(images, gts, sensor, cfg, log=print):
    """BFGS (optimistix) on the surrogate loss from the paper's settings; returns θ, history."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import optimistix as optx

    images = jnp.asarray(images, jnp.float32)
    gts = {k: jnp.asarray(gts[k], jnp.float32) for k in ("h_xyz", "v_xyz")}
    sensor32 = jax.tree_util.tree_map(
        lambda x: x.astype(jnp.float32) if eqx.is_inexact_array(x) else x, sensor
    )

    def fn(theta, args):
        return surrogate_loss(theta, *args, cfg), None

    args = (images, gts, sensor32)
    solver = optx.BFGS(rtol=cfg["rtol"], atol=cfg["atol"])
    y = jnp.asarray(pack(PAPER["weights"], PAPER["sigma"], PAPER["loading"]), jnp.float32)
    f_struct = jax.ShapeDtypeStruct((), jnp.float32)
    state = solver.init(fn, y, args, {}, f_struct, None, frozenset())

    @eqx.filter_jit
    def step(y, state):
        y, state, _ = solver.step(fn, y, args, {}, state, frozenset())
        done, result = solver.terminate(fn, y, args, {}, state, frozenset())
        return y, state, done, result

    history = []
    t0 = time.perf_counter()
    for k in range(cfg["bfgs_steps"] + 1):
        y_eval = state.y_eval
        y, state, done, result = step(y, state)
        # `state.f_info.f` is the loss at the last accepted point; the evaluated one is
        # y_eval's (accepted or not).
        f_acc = float(state.f_info.f)
        w, s, ld = unpack(y_eval)
        history.append(
            dict(
                step=k,
                loss_accepted=f_acc,
                accepted_steps=int(state.num_accepted_steps),
                w_r=float(w[0]),
                w_g=float(w[1]),
                w_b=float(w[2]),
                sigma=float(s),
                loading=float(ld),
                elapsed_s=time.perf_counter() - t0,
            )
        )
        log(
            f"  step {k:2d}: accepted loss {f_acc:.4f} mm  (eval at w=({w[0]:+.3f},{w[1]:+.3f},"
            f"{w[2]:+.3f}) σ={float(s):.3f} loading={float(ld):.2e})  "
            f"{time.perf_counter() - t0:.0f} s"
        )
        if bool(done) and k > 0:
            break
    if result != optx.RESULTS.successful:
        log(f"  BFGS result: {optx.RESULTS[result]}")
    return np.asarray(y), history


# ----------------------------------------------------------------------------- evaluation


def _render(kinds, nuisances, n, seed):
    """Frames per (kind, nuisance): seed + 10·k + j per condition, stated in the output."""
    from cslx.sim import render_dataset

    out = []
    for j, nuisance in enumerate(nuisances):
        for k, kind in enumerate(kinds):
            s = seed + 10 * k + j
            images, gt, sensor = render_dataset(kind, nuisance, n, seed=s)
            out.append((kind, nuisance, s, images, gt, sensor))
    return out


def _point_errors(uv, gt_xyz, sensor, plane):
    import jax.numpy as jnp

    from cslx.sensor import triangulate

    est = np.all(np.isfinite(uv), 1)
    has = np.all(np.isfinite(gt_xyz), 1)
    m = est & has
    if not m.any():
        return np.zeros(0), int(has.sum())
    xyz = np.asarray(triangulate(sensor, jnp.asarray(uv[m], sensor.planes.dtype), plane))
    err = np.linalg.norm(xyz - gt_xyz[m], axis=1)
    return np.where(np.isfinite(err), err, np.inf), int(has.sum())


def evaluate(sets, settings, stripes=("h", "v")):
    """Hard pipeline (`segment.extract(..., "med")`) with given settings; pooled metrics."""
    from cslx.segmentation import centres_to_pixels, extract

    rows = []
    for kind, nuisance, seed, images, gt, sensor in sets:
        for stripe in stripes:
            plane = 0 if stripe == "h" else 1
            errs, n_gt, times = [], 0, []
            for f in range(len(images)):
                t = time.perf_counter()
                c = extract(
                    images[f],
                    "med",
                    space=tuple(settings["weights"]),
                    stripe=stripe,
                    sigma=float(settings["sigma"]),
                    med_options=dict(loading=float(settings["loading"])),
                )
                uv = centres_to_pixels(c, stripe)
                times.append(time.perf_counter() - t)
                e, n = _point_errors(uv, gt[f"{stripe}_xyz"][f], sensor, plane)
                errs.append(e)
                n_gt += n
            err = np.concatenate(errs)
            nan = float("nan")
            rows.append(
                dict(
                    kind=kind,
                    nuisance=nuisance,
                    seed=seed,
                    stripe=stripe,
                    frames=len(images),
                    mean_mm=float(np.mean(err)) if len(err) else nan,
                    median_mm=float(np.median(err)) if len(err) else nan,
                    p95_mm=float(np.percentile(err, 95)) if len(err) else nan,
                    detection_rate=len(err) / n_gt if n_gt else nan,
                    gross_rate=float(np.mean(err > 1.0)) if len(err) else nan,
                    n_gt=n_gt,
                    ms_per_frame=1e3 * float(np.median(times[1:] or times)),
                )
            )
    return rows


# ----------------------------------------------------------------------------- main


def _settings(theta) -> dict:
    w, s, ld = unpack(np.asarray(theta))
    return dict(weights=tuple(float(x) for x in w), sigma=float(s), loading=float(ld))


def main(out: str = str(RESULTS), quick: bool = False, **overrides):
    """Tune on training scenes, evaluate on held-out ones; write CSV/MD/PNG; return rows."""
    import jax
    import jax.numpy as jnp

    from cslx.provenance import md_table, provenance, provenance_md, write_csv

    cfg = dict(CONFIG)
    if quick:
        cfg.update(QUICK)
    cfg.update(overrides)
    t_start = time.perf_counter()
    print("rendering training scenes …", flush=True)
    train_sets = _render(
        cfg["train_kinds"], cfg["train_nuisances"], cfg["train_frames"], cfg["train_seed"]
    )
    images = np.concatenate([s[3] for s in train_sets])
    gts = {k: np.concatenate([s[4][k] for s in train_sets]) for k in ("h_xyz", "v_xyz")}
    sensor = train_sets[0][5]

    print(f"training on {len(images)} frames ({cfg['bfgs_steps']} BFGS steps) …", flush=True)
    t = time.perf_counter()
    theta, history = train(images, gts, sensor, cfg)
    train_s = time.perf_counter() - t
    tuned = _settings(theta)
    paper = dict(PAPER)
    # Surrogate loss of the paper's settings and the tuned ones on the training set.
    print(f"tuned: {tuned}", flush=True)

    print("rendering held-out scenes …", flush=True)
    test_sets = _render(
        cfg["test_kinds"], cfg["test_nuisances"], cfg["test_frames"], cfg["test_seed"]
    )
    rows = []
    for split, sets in (("train", train_sets), ("held-out", test_sets)):
        # Ablation: the paper's colour space and loading with only σ tuned.
        sigma_only = dict(paper, sigma=tuned["sigma"])
        for name, settings in (("paper", paper), ("sigma-only", sigma_only), ("tuned", tuned)):
            print(f"evaluating {name} settings on {split} scenes …", flush=True)
            for r in evaluate(sets, settings, cfg["stripes"]):
                seen = r["nuisance"] in cfg["train_nuisances"] and r["kind"] in cfg["train_kinds"]
                rows.append(
                    dict(
                        split=split,
                        condition="seen kind" if seen else "UNSEEN kind",
                        settings=name,
                        **r,
                    )
                )
    total_s = time.perf_counter() - t_start
    prov = provenance({**cfg, "quick": quick})
    prov["train_s"] = train_s
    prov["total_s"] = total_s
    prov["jax_x64"] = bool(jax.config.jax_enable_x64)
    del jnp

    os.makedirs(out, exist_ok=True)
    fields = [
        "split",
        "condition",
        "kind",
        "nuisance",
        "seed",
        "stripe",
        "settings",
        "frames",
        "mean_mm",
        "median_mm",
        "p95_mm",
        "detection_rate",
        "gross_rate",
        "n_gt",
        "ms_per_frame",
    ]
    write_csv(os.path.join(out, "tune_differentiable.csv"), rows, fields)
    _plot(os.path.join(out, "tune_differentiable.png"), history, rows)
    md = _markdown(rows, history, paper, tuned, cfg, prov, md_table, provenance_md)
    with open(os.path.join(out, "tune_differentiable.md"), "w", encoding="utf-8") as f:
        f.write(md)
    print(md)
    print(f"done in {total_s:.0f} s (training {train_s:.0f} s)")
    return rows


def _paired(rows):
    """Pairs (paper row, tuned row) keyed by split/kind/nuisance/stripe."""
    key = ("split", "kind", "nuisance", "stripe")
    by = {}
    for r in rows:
        by.setdefault(tuple(r[k] for k in key), {})[r["settings"]] = r
    return [(k, v["paper"], v["tuned"]) for k, v in by.items() if {"paper", "tuned"} <= set(v)]


def _pooled(rows, split, settings, field):
    sel = [r for r in rows if r["split"] == split and r["settings"] == settings]
    w = np.array([r["n_gt"] * r["detection_rate"] for r in sel], float)
    x = np.array([r[field] for r in sel], float)
    ok = np.isfinite(x) & (w > 0)
    return float(np.sum(w[ok] * x[ok]) / np.sum(w[ok])) if ok.any() else float("nan")


def _markdown(rows, history, paper, tuned, cfg, prov, md_table, provenance_md):
    lines = ["# Tuning the pipeline's parameters by gradient (beyond the paper)", ""]
    lines += [
        "Colour weights (unit sphere), Steger σ and MED's diagonal loading were tuned by "
        "optimistix BFGS on `jax.grad` of a Huber (δ = "
        f"{cfg['huber_mm']} mm) 3-D error of a differentiable surrogate of the pipeline "
        f"(MED unrolled {cfg['med_steps']} steps, continuous-σ Steger, softmax centre "
        f"τ = {cfg['tau']}), on {len(cfg['train_kinds']) * len(cfg['train_nuisances'])} "
        f"training conditions × {cfg['train_frames']} frames "
        f"(kinds {', '.join(cfg['train_kinds'])}; nuisances "
        f"{', '.join(cfg['train_nuisances'])}; seeds from {cfg['train_seed']}). "
        "Both settings are then scored with the ordinary hard pipeline "
        "(`segment.extract(..., 'med')`, converged MED, Steger thresholds) on held-out "
        f"seeds (from {cfg['test_seed']}), including nuisance and scene kinds never used in "
        "training (marked UNSEEN). Errors are pooled over matched columns/rows; detection "
        "rate = matched / ground-truth columns (rows).",
        "",
        "## Parameters",
        "",
    ]
    prm = [
        dict(
            settings="paper (fixed)",
            w=f"({paper['weights'][0]:+.3f}, {paper['weights'][1]:+.3f}, "
            f"{paper['weights'][2]:+.3f})",
            sigma_px=paper["sigma"],
            loading=f"{paper['loading']:.2e}",
        ),
        dict(
            settings="tuned",
            w=f"({tuned['weights'][0]:+.3f}, {tuned['weights'][1]:+.3f}, "
            f"{tuned['weights'][2]:+.3f})",
            sigma_px=tuned["sigma"],
            loading=f"{tuned['loading']:.2e}",
        ),
    ]
    lines.append(md_table(prm, ["settings", "w", "sigma_px", "loading"]))
    lines += [
        "(the paper's R−G is (+0.707, −0.707, 0) on the unit sphere; scale does not matter "
        "after MED and Steger's relative thresholds)",
        "",
        f"Surrogate training loss: {history[0]['loss_accepted']:.4f} → "
        f"{history[-1]['loss_accepted']:.4f} mm over {len(history) - 1} BFGS steps "
        f"({prov['train_s']:.0f} s).",
        "",
        "## Pooled over conditions (matched-point weighted)",
        "",
    ]
    summ = []
    for split in ("train", "held-out"):
        for s in ("paper", "sigma-only", "tuned"):
            summ.append(
                dict(
                    split=split,
                    settings=s,
                    mean_mm=_pooled(rows, split, s, "mean_mm"),
                    gross_rate=_pooled(rows, split, s, "gross_rate"),
                    detection=np.mean(
                        [
                            r["detection_rate"]
                            for r in rows
                            if r["split"] == split and r["settings"] == s
                        ]
                    ),
                )
            )
    lines.append(md_table(summ, ["split", "settings", "mean_mm", "gross_rate", "detection"]))
    lines += [
        "",
        "`sigma-only` is the ablation: the paper's R−G and loading with only the tuned σ; it "
        "tells how much of the change is due to σ alone.",
    ]
    lines += ["", "## Per condition (paper → tuned)", ""]
    per = []
    for (split, kind, nuisance, stripe), p, t in _paired(rows):
        per.append(
            dict(
                split=split,
                condition=t["condition"],
                kind=kind,
                nuisance=nuisance,
                stripe=stripe,
                mean_mm=f"{p['mean_mm']:.3f} → {t['mean_mm']:.3f}",
                median_mm=f"{p['median_mm']:.3f} → {t['median_mm']:.3f}",
                p95_mm=f"{p['p95_mm']:.3f} → {t['p95_mm']:.3f}",
                detection=f"{p['detection_rate']:.3f} → {t['detection_rate']:.3f}",
                gross=f"{p['gross_rate']:.3f} → {t['gross_rate']:.3f}",
            )
        )
    lines.append(
        md_table(
            per,
            [
                "split",
                "condition",
                "kind",
                "nuisance",
                "stripe",
                "mean_mm",
                "median_mm",
                "p95_mm",
                "detection",
                "gross",
            ],
        )
    )
    lines += ["", "## Verdict", "", _verdict(rows), "", "## Provenance", "", provenance_md(prov)]
    lines.append(f"- total run time {prov['total_s']:.0f} s; training {prov['train_s']:.0f} s")
    return "\n".join(lines) + "\n"


def _verdict(rows) -> str:
    """A sentence computed from the numbers (no hand-written claim)."""
    out = []
    for split in ("train", "held-out"):
        p = _pooled(rows, split, "paper", "mean_mm")
        t = _pooled(rows, split, "tuned", "mean_mm")
        pairs = [(pp, tt) for (s, *_), pp, tt in _paired(rows) if s == split]
        better = sum(tt["mean_mm"] < pp["mean_mm"] for pp, tt in pairs)
        worse_det = sum(tt["detection_rate"] < pp["detection_rate"] - 0.01 for pp, tt in pairs)
        rel = 100 * (p - t) / p if p else float("nan")
        word = "no measurable change" if abs(rel) < 1 else ("gain" if t < p else "LOSS")
        out.append(
            f"- {split}: pooled mean error {p:.3f} mm (paper) vs {t:.3f} mm (tuned), "
            f"{rel:+.1f} % ({word}); tuned mean error lower in "
            f"{better} of {len(pairs)} condition×stripe cells; detection rate more than "
            f"1 point lower in {worse_det}."
        )
    for split in ("train", "held-out"):
        a = _pooled(rows, split, "sigma-only", "mean_mm")
        t = _pooled(rows, split, "tuned", "mean_mm")
        out.append(
            f"- ablation, {split}: σ alone (R−G, paper loading) gives {a:.3f} mm vs "
            f"{t:.3f} mm with all tuned parameters."
        )
    out += [
        "",
        "Caveats: the mean is dominated by a few gross outliers per condition (compare the "
        "medians and p95 in the table); the surrogate (unrolled MED, softmax centre) and the "
        "hard pipeline (converged MED, thresholds) differ, so a lower surrogate loss need "
        "not transfer cell by cell; the loss is rugged in the colour weights (MED can switch "
        "to another fixed point after a small change of w, making a frame's error jump), so "
        "w moves little and its change should not be read as a better colour space; MED's "
        "diagonal loading has a negligible gradient at 1e-5 and stays put; the fixed budget "
        "of BFGS steps may stop before convergence (see the loss curve).",
    ]
    return "\n".join(out)


def _plot(path, history, rows):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    ax = axes[0]
    ax.plot([h["step"] for h in history], [h["loss_accepted"] for h in history], "o-")
    ax.set_xlabel("BFGS step")
    ax.set_ylabel("training loss (Huber, mm)")
    ax.set_title("surrogate loss (last accepted point)", fontsize=9)
    ax = axes[1]
    steps = [h["step"] for h in history]
    for key in ("w_r", "w_g", "w_b", "sigma"):
        ax.plot(steps, [h[key] for h in history], label=key)
    ax.plot(steps, [math.log10(h["loading"]) for h in history], label="log10 loading")
    ax.set_xlabel("BFGS step (evaluated point)")
    ax.legend(fontsize=7)
    ax.set_title("parameters", fontsize=9)
    ax = axes[2]
    held = [r for r in rows if r["split"] == "held-out"]
    labels = sorted({(r["nuisance"], r["kind"], r["stripe"]) for r in held})
    x = np.arange(len(labels))
    for off, s, colour in ((-0.2, "paper", "tab:gray"), (0.2, "tuned", "tab:red")):
        vals = []
        for lab in labels:
            r = [
                r
                for r in held
                if r["settings"] == s and (r["nuisance"], r["kind"], r["stripe"]) == lab
            ]
            vals.append(r[0]["mean_mm"] if r else np.nan)
        ax.bar(x + off, vals, 0.4, color=colour, label=s)
    ax.set_xticks(x, [f"{n}\n{k[:5]} {s}" for n, k, s in labels], fontsize=6)
    ax.set_ylabel("held-out mean 3-D error (mm)")
    ax.set_title("held-out scenes, hard pipeline", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--quick", action="store_true", help="tiny run (CI smoke test)")
    p.add_argument("--out", default=str(RESULTS), help="output directory (default results/)")
    p.add_argument("--steps", type=int, default=None, help="BFGS steps")
    a = p.parse_args()
    kw = {} if a.steps is None else dict(bfgs_steps=a.steps)
    main(out=a.out, quick=a.quick, **kw)
