"""Process recorded inspections (thousands of frames) over every available device.

The frame batch is split along its leading axis over a one-axis device mesh with JAX's own
sharding (`jax.sharding.Mesh`, `NamedSharding`, `PartitionSpec("frames")`); one jit-compiled
`jax.shard_map` runs the per-frame function on each device's share of the frames where the
data lies (vmapped on accelerators, mapped frame by frame on the CPU where vmap was slower,
`default_vmap_size`), and the results are gathered back to the host. Nothing here distributes work
by hand: the same code runs on one CPU, on several devices of one host (GPUs, or CPU devices
forced with ``XLA_FLAGS=--xla_force_host_platform_device_count=N``) and on several hosts
after `initialize_distributed` (`jax.distributed.initialize`), where every process passes the
same frames and each places only the shards of its own devices.

`process_archive(frames, fn)` is the general entry point; `extract_batch` is `cslx extract`'s
batched path (the JAX methods "steger" and "med" of `cslx.segmentation.extract.extract`).

Frames are independent here (an archive, not a video): MED starts cold on every frame, as
`cslx.segmentation.extract` does. Video tracking, where each frame warm-starts from the last, is
sequential and belongs to `cslx.runtime.tracker`.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable, Sequence
from typing import Any

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P
from jaxtyping import Array, ArrayLike

__all__ = [
    "AXIS",
    "default_vmap_size",
    "device_summary",
    "JAX_METHODS",
    "extract_batch",
    "frame_mesh",
    "initialize_distributed",
    "map_frames",
    "platform_vmap_size",
    "place_frames",
    "process_archive",
]

#: Name of the mesh axis the frames are split along.
AXIS = "frames"
#: Methods of `cslx.segmentation.extract.extract` that are pure JAX and can be vmapped and sharded.
JAX_METHODS = ("steger", "med")

_DISTRIBUTED_ENV = ("JAX_COORDINATOR_ADDRESS", "SLURM_JOB_ID", "OMPI_COMM_WORLD_SIZE")


def initialize_distributed() -> bool:
    """Join a multi-host JAX job when one is configured; True if this process is in one.

    Calls `jax.distributed.initialize()` (which reads the coordinator, process count and
    id from the environment: ``JAX_COORDINATOR_ADDRESS``, ``JAX_NUM_PROCESSES``,
    ``JAX_PROCESS_ID``, or a SLURM / Open MPI launch) once, and only when one of those
    environments is present; a single machine needs nothing. Idempotent.
    """
    if jax.process_count() > 1:
        return True
    if not any(k in os.environ for k in _DISTRIBUTED_ENV):
        return False
    jax.distributed.initialize()
    return jax.process_count() > 1


def frame_mesh(devices: Sequence[jax.Device] | None = None) -> Mesh:
    """A one-axis mesh named `AXIS` over `devices` (default: every device of every host)."""
    devices = list(jax.devices() if devices is None else devices)
    if not devices:
        raise ValueError("frame_mesh needs at least one device")
    return Mesh(np.asarray(devices, dtype=object), (AXIS,))


def place_frames(batch: ArrayLike, mesh: Mesh) -> jax.Array:
    """Put a batch (leading axis a multiple of the mesh size) on the mesh, split by frames.

    One process: `jax.device_put` with `NamedSharding(mesh, P(AXIS))`. Several processes:
    every process holds the same batch and builds only its own devices' shards
    (`jax.make_array_from_callback`).
    """
    batch = np.asarray(batch)
    n = mesh.devices.size
    if batch.ndim < 1 or batch.shape[0] % n:
        raise ValueError(
            f"the frame axis ({batch.shape[0] if batch.ndim else 'none'}) must be a multiple "
            f"of the {n} devices of the mesh; process_archive pads it"
        )
    sharding = NamedSharding(mesh, P(AXIS))
    if jax.process_count() == 1:
        return jax.device_put(batch, sharding)
    return jax.make_array_from_callback(batch.shape, sharding, lambda index: batch[index])


def platform_vmap_size(platforms) -> int | None:
    """Frames vectorised together on devices of these platforms: 1 on the CPU, all elsewhere.

    On this 2-core CPU, `vmap` over frames made the per-frame cost of MED + Steger grow
    with the batch (52 → 121 ms/frame from 1 to 8 frames, `results/bench_scaling.csv`;
    `lax.map` over the same 8 frames was 2.2× faster than `vmap` in one run): the working
    set of a batch leaves the cache, every fixed-point loop runs until the slowest frame
    has converged, and `lax.cond` evaluates both branches. GPUs want the whole batch
    vectorised.
    """
    return 1 if set(platforms) == {"cpu"} else None


def default_vmap_size(mesh: Mesh) -> int | None:
    """Frames vmapped together per device of the mesh (`platform_vmap_size`)."""
    return platform_vmap_size(d.platform for d in mesh.devices.flat)


def map_frames(fn: Callable, frames, vmap_size: int | None = None):
    """``fn`` over the leading axis: `vmap` (``vmap_size`` None or ≥ the batch) or `lax.map`
    vectorising ``vmap_size`` frames at a time (frame by frame for 1). Traceable."""
    if vmap_size is None or vmap_size >= frames.shape[0]:
        return jax.vmap(fn)(frames)
    return jax.lax.map(fn, frames, batch_size=vmap_size)


@functools.lru_cache(maxsize=32)
def _compiled(fn: Callable, mesh: Mesh, vmap_size: int | None) -> Callable:
    """jit of a `shard_map` over the frame axis: each device maps ``fn`` over its frames.

    ``vmap_size`` frames are vectorised together (`lax.map` with ``batch_size``); None
    vectorises all of a device's frames (plain `vmap`).
    """

    def local(frames):
        return map_frames(fn, frames, vmap_size)

    # check_vma=False: optimistix's fixed point builds its initial carry from constants,
    # which shard_map's varying-axis check would reject; every frame is independent here.
    spec = P(AXIS)
    return jax.jit(jax.shard_map(local, mesh=mesh, in_specs=spec, out_specs=spec, check_vma=False))


def _gather(tree: Any) -> Any:
    if jax.process_count() == 1:
        return jax.device_get(tree)
    from jax.experimental import multihost_utils

    return multihost_utils.process_allgather(tree, tiled=True)


def process_archive(
    frames: ArrayLike,
    fn: Callable[[Array], Any],
    *,
    batch_size: int | None = None,
    devices: Sequence[jax.Device] | None = None,
    vmap_size: int | None | str = "auto",
    progress: Callable[[int, int], None] | None = None,
) -> Any:
    """Apply a per-frame function to every frame, sharded over the devices; results on host.

    The F frames go through in batches of ``batch_size`` (rounded up to a multiple of the
    device count; the last batch is padded with copies of its last frame so that one
    compiled program serves every batch, and the padding is dropped from the results).
    Each batch is placed with `place_frames` (split along the frame axis) and run by one
    jit-compiled `jax.shard_map`: every device maps ``fn`` over its own frames, ``vmap_size``
    at a time (vectorised with vmap), with the outputs sharded the same way; then gathered.

    Args:
        frames: (F, ...) frames, e.g. (F, H, W, 3) uint8 RGB; NumPy or JAX.
        fn: pure JAX function of one frame (no leading axis) returning a pytree of arrays.
            Pass the same function object each time to reuse the compiled program.
        batch_size: frames per device step (default: 8 per device, at most F rounded up).
        devices: devices to use (default `jax.devices()`: all of them, on every host).
        vmap_size: frames vectorised together on a device; None = all of its frames (plain
            vmap); "auto" = `default_vmap_size` (1 on the CPU, all on accelerators).
        progress: optional callback ``progress(done, total)`` after each batch.

    Returns:
        The pytree of `fn` with a leading axis F on every leaf, as NumPy arrays.
    """
    frames = np.asarray(frames)
    if frames.ndim < 1 or frames.shape[0] == 0:
        raise ValueError(f"expected a non-empty batch of frames (F, ...), got shape {frames.shape}")
    mesh = frame_mesh(devices)
    n_dev = mesh.devices.size
    total = frames.shape[0]
    if batch_size is None:
        batch_size = min(8 * n_dev, total)
    if batch_size < 1:
        raise ValueError(f"batch_size must be positive, got {batch_size}")
    batch_size = -(-batch_size // n_dev) * n_dev
    if vmap_size == "auto":
        vmap_size = default_vmap_size(mesh)
    run = _compiled(fn, mesh, vmap_size)
    parts = []
    for start in range(0, total, batch_size):
        chunk = frames[start : start + batch_size]
        n = chunk.shape[0]
        if n < batch_size:
            pad = np.repeat(chunk[-1:], batch_size - n, axis=0)
            chunk = np.concatenate([chunk, pad])
        out = _gather(run(place_frames(chunk, mesh)))
        parts.append(jax.tree_util.tree_map(lambda x, n=n: np.asarray(x)[:n], out))
        if progress is not None:
            progress(min(start + batch_size, total), total)
    return jax.tree_util.tree_map(lambda *xs: np.concatenate(xs), *parts)


@functools.lru_cache(maxsize=32)
def _extract_fn(method: str, space: Any, stripe: str, sigma: float) -> Callable:
    from .interface import extract

    def one(rgb):
        c = extract(rgb, method, space=space, stripe=stripe, sigma=sigma)
        return c.pos, c.valid, c.strength

    return one


def extract_batch(
    frames: ArrayLike,
    method: str = "med",
    *,
    space: str | tuple[float, float, float] = "r-g",
    stripe: str = "h",
    sigma: float = 2.0,
    batch_size: int | None = None,
    devices: Sequence[jax.Device] | None = None,
    vmap_size: int | None | str = "auto",
    progress: Callable[[int, int], None] | None = None,
):
    """`cslx.segmentation.extract.extract` on a batch of frames, sharded over the devices.

    Args:
        frames: (F, H, W, 3) RGB frames of one size (uint8 or float).
        method: "steger" or "med" (`JAX_METHODS`; the NumPy baselines cannot be sharded).
        space: colour space name or weights, as `cslx.segmentation.extract.extract` ("auto" is per
            frame and not supported here).
        stripe: "h" (one centre per column) or "v" (one per row).
        sigma: Steger's scale, px.
        batch_size, devices, vmap_size, progress: as `process_archive`.

    Returns:
        `Centres` with NumPy fields of shape (F, N): the same values as calling
        `extract` frame by frame.
    """
    from .colour import parse_space
    from .steger import Centres

    if method not in JAX_METHODS:
        raise ValueError(f"extract_batch runs the JAX methods {JAX_METHODS}, not {method!r}")
    if stripe not in ("h", "v"):
        raise ValueError(f"stripe must be 'h' or 'v', got {stripe!r}")
    if isinstance(space, str):
        weights = parse_space(space)
        if weights == "auto":
            raise ValueError("extract_batch needs fixed colour weights; 'auto' searches per frame")
    else:
        weights = space
    weights = tuple(float(w) for w in np.asarray(weights, float).ravel())
    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3:
        raise ValueError(f"expected RGB frames of shape (F, H, W, 3), got shape {frames.shape}")
    fn = _extract_fn(method, weights, stripe, float(sigma))
    pos, valid, strength = process_archive(
        frames, fn, batch_size=batch_size, devices=devices, vmap_size=vmap_size, progress=progress
    )
    return Centres(pos, valid, strength)


def device_summary() -> str:
    """One line naming the devices a sharded run would use."""
    devs = jax.devices()
    kinds = sorted({f"{d.platform}:{getattr(d, 'device_kind', '')}" for d in devs})
    return f"{len(devs)} device(s) on {jax.process_count()} process(es): {', '.join(kinds)}"
