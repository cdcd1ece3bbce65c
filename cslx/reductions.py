"""The first maximum along an axis as ONE integer max reduction (Steger's selection, peaks).

``jnp.argmax`` is a variadic (value, index) reduction that XLA's CPU backend does not
vectorise: ≈ 3× the time of a max on a 640×480 frame (issue 13). The library used to take
the maximum and then the smallest index whose value equals it, two plain reductions — but
that equality is between two computations of the same values: XLA fuses the producer of
the values into each reduction that reads them and may compute them differently in each
fusion. Compiled at LLVM's -O0 (the test session), a column's recomputed Steger strength
differed from its own maximum in the last bit, and the column lost its centre
(`lax.optimization_barrier` does not help: XLA's CPU pipeline removes it before fusion).

`first_argmax` needs no equality: each value is mapped to an integer of the same order
(`ordered_int`: the float's bits, the negative ones flipped), the low ``k`` bits are
replaced by the reversed index (k = ⌈log₂ n⌉), and one integer max reduction returns
a key from which the index is read back. The order of the values is kept except between
values equal in all but the low ``k`` bits of their representation: there the first index
wins, as in an exact tie (float32 and 480 samples: relative differences below 2⁻¹⁴ ≈ 6e-5;
float64: below 2⁻⁴³). NaN ranks above +∞ (``jnp.argmax`` also returns a NaN's index).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax.numpy as jnp
from jax import lax

if TYPE_CHECKING:  # annotations only (strings at run time): no jaxtyping import
    from jaxtyping import Array, Bool, Float, Int

__all__ = ["first_argmax", "ordered_int"]

_INT_OF = {2: jnp.int16, 4: jnp.int32, 8: jnp.int64}


def ordered_int(x: Float[Array, "*shape"]) -> Int[Array, "*shape"]:
    """Signed integers with the order of the floats ``x`` (−0 just below +0, NaN above +∞)."""
    itype = _INT_OF[jnp.dtype(x.dtype).itemsize]
    bits = lax.bitcast_convert_type(lax.stop_gradient(x), itype)
    top = jnp.iinfo(itype).max
    # negative floats order backwards as integers: flipping all but the sign bit reverses them
    o = jnp.where(bits < 0, bits ^ jnp.asarray(top, itype), bits)
    return jnp.where(jnp.isnan(x), jnp.asarray(top, itype), o)


def first_argmax(
    x: Float[Array, "*shape"], axis: int = -1, where: Bool[Array, "*shape"] | None = None
) -> tuple[Int[Array, "*shape"], Bool[Array, "*shape"]]:
    """(index of the first maximum of ``x`` along ``axis``, whether any entry counted).

    ``where`` (broadcast against ``x``) excludes entries; a line with none left gives
    index 0 and False. Ties, and values equal to the key's resolution (module docstring),
    go to the smallest index, like ``jnp.argmax``. Integer outputs, no gradient.
    """
    axis = axis % x.ndim
    n = x.shape[axis]
    k = max(1, (n - 1).bit_length())
    o = ordered_int(x)
    itype = o.dtype
    low = jnp.asarray((1 << k) - 1, itype)
    index = lax.broadcasted_iota(itype, x.shape, axis)
    key = (o & ~low) | (low - index)
    lowest = jnp.iinfo(itype).min
    if where is not None:
        key = jnp.where(where, key, jnp.asarray(lowest, itype))
    best = _max_last(key) if axis == x.ndim - 1 else jnp.max(key, axis=axis)
    found = best != lowest if where is not None else jnp.ones(best.shape, bool)
    i = low - (best & low)
    return jnp.where(found, i, 0).astype(jnp.int32), found


def _max_last(key: Int[Array, "*shape n"]) -> Int[Array, "*shape"]:
    """``jnp.max(key, axis=-1)``, halving the axis by elementwise maxima down to ≤ 16 first.

    XLA's CPU backend reduces a minor axis as a reduce-window of 32 and a reduce, one
    element at a time; the halvings are one vectorised elementwise fusion (a max is exact:
    the same values). Issue 13, Steger's selection along the rows of the 480×128 band of
    columns: the reduction alone 98 → 68 µs p10 (500 interleaved calls, load 10);
    `steger_centres` on that band paired −34 and −19 µs in two runs (600 interleaved calls,
    load 9; the 64×640 band, reduced along its columns and unchanged, moved −5 and +35 µs:
    the noise), the tracking frame paired −0.089 ms, `Tracker.step` −0.000 ms
    (`experiments.ab_tracking`, 300 frames, load 9–11); outputs identical.
    """
    while key.shape[-1] > 16 and key.shape[-1] % 2 == 0:
        h = key.shape[-1] // 2
        key = jnp.maximum(key[..., :h], key[..., h:])
    return jnp.max(key, axis=-1)
