"""The tracker's compiled step: the pipeline on one frame, its summary and the new state.

`cslx.runtime.tracker.Tracker` runs it every frame; one program per (Steger σ, colour
weights) (`cslx.runtime.stripe_width`, `cslx.runtime.stripe_colour`). Built by
`cslx.runtime.compiled.cached_program`, so a cached start-up neither imports the pipeline
nor traces it.
"""

from __future__ import annotations

from collections.abc import Callable

__all__ = ["EXTRA_FIELDS", "step_program"]

#: Values the tracker's compiled step returns after `cslx.runtime.pipeline.SUMMARY_FIELDS`.
EXTRA_FIELDS = ("v_height_mm", "v_width_mm")


def step_program(sensor32, config: Callable[[], object], setting: str, roi: bool, shape):
    """``(call, args, meta)`` of `cslx.runtime.compiled.cached_program` for the step.

    Args:
        sensor32: the float32 sensor the program closes over.
        config: returns the `cslx.runtime.pipeline.PipelineConfig` (called only to build).
        setting: names the configuration in the cache key (``repr`` of it, or a name).
        roi: allow tracking mode (`cslx.runtime.pipeline.process_frame`).
        shape: (H, W, 3) of the frames.

    ``call(rgb, *state)`` returns (summary, points_h, points_v, *new state); ``args[1:]``
    is the initial state; ``meta`` holds the summary's field names, the program's σ (px)
    and the colour weights.
    """
    import jax
    import jax.numpy as jnp

    from .compiled import cached_program, tree_digest

    height, width = shape[:2]

    def build():
        # Only when the program is not in the cache folder: a cached start-up neither
        # imports the pipeline (equinox modules, MED, Steger, weld: ≈ 0.1–0.2 s) nor
        # traces it; the initial state and the meta data come from the file.
        from . import pipeline as pl

        config_ = config()
        init = jax.jit(pl.init_state, static_argnums=(0, 1, 2))
        state0 = init(config_, (width, height), jnp.float32)
        leaves, treedef = jax.tree_util.tree_flatten(state0)

        def step(rgb, *state):
            result, new = pl._process(sensor32, config_, rgb, treedef.unflatten(state), roi)
            fv = result.feature_v
            extra = jnp.stack([fv.height, fv.width]).astype(jnp.float32)
            summary = jnp.concatenate([pl.frame_summary(result), extra])
            return (summary, result.points_h, result.points_v, *jax.tree_util.tree_leaves(new))

        spec = jax.ShapeDtypeStruct(shape, jnp.uint8)
        meta = dict(
            fields=[*pl.SUMMARY_FIELDS, *EXTRA_FIELDS],
            sigma=float(pl._frame_config(config_, height, width).sigma),
            weights=list(config_.weights),
        )
        return step, (spec, *leaves), meta

    key = f"tracker|{setting}|{roi}|{tuple(shape)}|{tree_digest(sensor32)}"
    return cached_program(key, build)
