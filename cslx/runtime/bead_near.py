"""The followed bead near the filter's prediction, when the profile's largest bead is another.

The compiled pipeline takes the horizontal stripe's bead as the run with the largest area
(`cslx.runtime.bead_run.largest_run`). Where a second weld crosses the horizontal stripe
beside the followed one, that is the wrong bead whenever the other is larger: a T whose bar
meets the stem at an angle other than 90° lies across the horizontal stripe, wide (its
width / sin of the angle between bar and stripe), for the last ≈ w / tan of that angle of
the stem before the junction. The filter's gate rejects it, but after `give_up_after`
rejections in a row it restarts there. Issue 12 audit (experiments/tracking_generality.py,
fresh seed 7400, clean, T at 60°): the bar's run 25–35 mm wide against the stem's 15 mm
on the last 9 frames before the junction reached the horizontal stripe, 7 gated frames,
then a restart 52.7 mm off the stem (offset max 52.7 mm, mean 2.69 mm over 40 frames).

`bead_near` refits the bead (`cslx.runtime.weld.stripe_feature`, the same detector and
settings) on the profile without the points above the plate farther than ``half_mm`` from
the predicted line (the other beads; the plate stays whole for the plate fit), so the run
is chosen by where the followed weld should be rather than by size; the tracker uses
that bead if the gate accepts it (`Tracker` with `KalmanConfig.near_refit_mm` > 0). The
window's half width is half the recent beads' median width plus `near_refit_mm`, which
leaves room for the prediction's error and the bead's toes.

Runs on the host's request only on a gated frame, as a program compiled when the tracker
starts (`near_program`; once per process, profile length and detector settings, reloaded
from the cache folder like the step itself): compiled on the first gated frame instead, it
stalled that frame by its compile (9 s CPU, 20 s wall at load 9 on the 2-core machine), far
past the controller's 0.5 s without a confident observation.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np

from .line_filter import width_weight
from .weld import (
    HORIZONTAL_AXIS,
    VERTICAL_AXIS,
    WeldConfig,
    WeldFeature,
    plate_fit,
    stripe_feature,
)

if TYPE_CHECKING:  # annotations only (strings at run time): no jaxtyping import
    from jaxtyping import Array, Float

__all__ = ["bead_near", "near_for", "near_program", "refit_near"]

#: `near_program`'s compiled programs in this process, by (settings, profile length).
_PROGRAMS: dict[tuple[str, int], Callable] = {}


@jax.jit
def bead_near(
    points: Float[Array, "n 3"],
    offset_mm: Float[Array, ""],
    slope: Float[Array, ""],
    x_ref: Float[Array, ""],
    half_mm: Float[Array, ""],
    config: WeldConfig = WeldConfig(),
) -> WeldFeature:
    """The horizontal stripe's bead among the points near the predicted weld line.

    Args:
        points: (W, 3) the horizontal stripe's robot-frame points, mm (NaN where none).
        offset_mm, slope: the predicted line y_r = offset + slope · (x_r − x_ref)
            (the filter's e and tan θ).
        x_ref: where the offset is taken, mm.
        half_mm: points farther than this from the line (along y_r) are left out.
        config: the bead detector's settings (the pipeline's `PipelineConfig.weld`).
    Returns:
        `WeldFeature` as `cslx.runtime.weld.stripe_feature` (position = y_r).
    """
    x, y = points[:, VERTICAL_AXIS], points[:, HORIZONTAL_AXIS]
    y_pred = offset_mm + slope * (x - x_ref)
    valid = jnp.all(jnp.isfinite(points), axis=1)
    # the plate line from the whole profile (a window of the bead and 8 mm of plate either
    # side leaves the robust plate fit half bead: heights 30 % low, noise ×30 on the test
    # profile), then only the points above it far from the line are left out
    P = jnp.where(valid[:, None], points, 0.0)
    w0 = valid.astype(P.dtype)
    s = jnp.where(valid, y - jnp.sum(w0 * y) / jnp.maximum(jnp.sum(w0), 1.0), 0.0)
    (c0, c1), _ = plate_fit(s, P[:, 2], valid, config)
    h = (P[:, 2] - c0 - c1 * s) / jnp.sqrt(1.0 + c1 * c1)
    far = jnp.abs(y - y_pred) > half_mm
    valid = valid & ~(far & (h > config.threshold_mm))
    return stripe_feature(points, valid, HORIZONTAL_AXIS, config, one_call=True)


def refit_near(raw: dict, points_h: np.ndarray, tracker, config: WeldConfig) -> bool:
    """On a frame whose bead the gate would reject, replace it in `raw` (the pipeline's
    summary: ``h_x_mm``, ``h_y_mm``, ``h_width_mm``, ``h_height_mm``, ``h_confidence``;
    ``h_near`` = 1 marks it) by the bead near the predicted line if the gate accepts that
    one. `tracker` gives the filter, the recent bead widths and `KalmanConfig`
    (`near_refit_mm`, `width_tol`). Returns whether it replaced the bead."""
    kf, c = tracker.filter, tracker.kalman
    if c.near_refit_mm <= 0 or not kf.initialised or not tracker._widths:
        return False
    half = 0.5 * float(np.median(tracker._widths)) + c.near_refit_mm
    line = (kf.x[0], math.tan(kf.x[1]), tracker.x_ref, half)
    near = tracker._near or near_program(lambda: config, repr(config), points_h.shape[0])
    f = near(np.asarray(points_h, np.float32), *(np.float32(v) for v in line))
    x, y, conf = float(f.centre[0]), float(f.centre[1]), float(f.confidence)
    width = float(f.width)
    w = width_weight(width, tracker._widths, c.width_tol)
    if not (bool(f.found) and conf > 0 and kf.innovation_ok(x, y, conf * w)):
        return False
    raw.update(h_x_mm=x, h_y_mm=y, h_width_mm=width, h_height_mm=float(f.height))
    raw.update(h_confidence=conf, h_near=1.0)
    return True


def near_program(config: Callable[[], WeldConfig], setting: str, n_points: int) -> Callable:
    """`bead_near` compiled for ``n_points`` float32 points and the settings ``config()``
    (called only to build), named ``setting`` in the cache key: ``call(points, offset,
    slope, x_ref, half)`` (float32 arrays) → `WeldFeature`. Kept in this process and, with
    a cache folder, on disk (`cslx.runtime.compiled.cached_program`)."""
    key = (setting, int(n_points))
    if key not in _PROGRAMS:
        from .compiled import cached_program

        def build():
            weld = config()

            def flat(points, offset_mm, slope, x_ref, half_mm):
                return tuple(bead_near(points, offset_mm, slope, x_ref, half_mm, weld))

            scalar = jax.ShapeDtypeStruct((), jnp.float32)
            return flat, (jax.ShapeDtypeStruct((n_points, 3), jnp.float32),) + (scalar,) * 4, {}

        call, _, _ = cached_program(f"bead_near|{setting}|{n_points}", build)
        _PROGRAMS[key] = lambda *a: WeldFeature(*call(*a))
    return _PROGRAMS[key]


def near_for(tracker) -> Callable | None:
    """The tracker's `near_program` (its profile length and weld settings), compiled when it
    starts; None when its `KalmanConfig.near_refit_mm` turns the refit off."""
    if tracker.kalman.near_refit_mm <= 0:
        return None
    own = tracker._config  # None: the default settings, named (no pipeline import to name them)
    setting = "tracking_config().weld" if own is None else repr(own.weld)
    return near_program(lambda: tracker.config.weld, setting, tracker.image_shape[1])
