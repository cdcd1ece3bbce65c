"""`process_batch`: the per-frame pipeline (`cslx.runtime.pipeline`) over a stack of frames.

Two ways through a batch on the CPU (one frame at a time; `vmap` made the per-frame cost
grow with the batch there, `cslx.segmentation.shard.platform_vmap_size`):

- ``warm=True`` (the default): the frames in order (`lax.scan`), each frame's MED started
  from the filters the frame before converged to (eqs. (18)–(24), the warm start of
  `PipelineState`, docs/corrections.md, 5). The band positions are not carried: every frame
  is still processed as one without tracking state. MED is a fixed point; on consecutive
  video frames a warm start reaches the same fixed point in fewer steps (≈ 5 instead of
  10–13 per stripe), so the per-frame cost falls as the batch grows (issue 13). The
  centres agree with independent processing (tests/runtime/test_batch.py).
- ``warm=False``: every frame from the same start state (`lax.map`), the frames fully
  independent.

On other platforms the whole batch is vectorised (`vmap`) from the same start state.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, UInt8

from ..segmentation.shard import map_frames, platform_vmap_size
from ..sensor import Sensor
from .pipeline import FrameResult, PipelineConfig, PipelineState, _check_frame, _process, init_state

__all__ = ["process_batch"]


def _filters(s: PipelineState):
    return s.filter_h, s.filter_v, s.roi_filter_h, s.roi_filter_v


@functools.partial(jax.jit, static_argnames=("roi", "vmap_size", "warm"))
def _process_batch(sensor, config, frames, state, roi, vmap_size, warm):
    if warm and vmap_size == 1:

        def body(start, rgb):
            result, new = _process(sensor, config, rgb, start, roi)
            # Only the MED filters travel to the next frame; the bands start afresh.
            return eqx.tree_at(_filters, state, _filters(new)), (result, new)

        return lax.scan(body, state, frames)[1]
    return map_frames(lambda f: _process(sensor, config, f, state, roi), frames, vmap_size)


def process_batch(
    sensor: Sensor,
    config: PipelineConfig,
    frames: UInt8[Array, "f h w 3"],
    state: PipelineState | None = None,
    *,
    roi: bool = False,
    vmap_size: int | None | str = "auto",
    warm: bool = True,
) -> tuple[FrameResult, PipelineState]:
    """`process_frame` on a stack of frames; results and states carry a leading frame axis.

    Args:
        sensor, config: as `process_frame`.
        frames: (F, H, W, 3) uint8 RGB frames.
        state: the start state; default `init_state` (cold MED filters, `PipelineConfig.start`).
        roi: allow the bands of the first pass (`process_frame`); False processes the full
            frame.
        vmap_size: frames vectorised together (`cslx.segmentation.shard.map_frames`);
            "auto" is one at a time on the CPU and the whole batch elsewhere.
        warm: with one frame at a time, start each frame's MED from the previous frame's
            converged filters (module docstring); False starts every frame from ``state``.
    """
    frames = jnp.asarray(frames)
    if frames.ndim != 4:
        raise ValueError(f"expected frames of shape (F, H, W, 3), got shape {frames.shape}")
    _check_frame(sensor, frames[0])
    if state is None:
        state = init_state(config, sensor.camera.image_size)
    if vmap_size == "auto":
        vmap_size = platform_vmap_size(d.platform for d in frames.devices())
    return _process_batch(sensor, config, frames, state, roi, vmap_size, bool(warm))
