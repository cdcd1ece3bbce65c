"""Shared settings, each with one home; the library, the CLI and the experiments read them here.

Settings are frozen dataclasses (hashable, so they can be static arguments of `jax.jit`) and
this module imports neither NumPy nor JAX, so the command line reads its defaults and help
texts from it without paying for JAX at start-up.

- `Stripe`: the two laser stripes of the cross, with the image axis each is searched along
  and the laser plane each belongs to. Use it instead of "h"/"v", axis numbers or plane
  indices.
- `Motion`: the robot's nominal speed and the camera's frame rate (the paper's 30 mm/s at
  20 fps).
- `Rig`: the default rig's geometry that other settings depend on (the look-ahead of the
  horizontal stripe in front of the robot's reference point).
- Values the offline detector (`cslx.segmentation`) and the tracker's first-frame checks
  (`cslx.runtime.stripe_colour`, `cslx.runtime.stripe_width`) share: the colour-space grid,
  the clipped level, the search stride and the σ ceiling.
"""

from __future__ import annotations

import dataclasses
import enum
import itertools

__all__ = [
    "CLIP_LEVEL",
    "COLOUR_GRID",
    "MOTION",
    "RIG",
    "SEARCH_CLIP_LEVEL",
    "SEARCH_STRIDE",
    "SIGMA_MAX",
    "Motion",
    "Rig",
    "Stripe",
]

#: The paper's grid of monochromatic spaces (section 3.1, correction 8): weights (w_r, w_g,
#: w_b) of eq. (8) with w_r ∈ {0, 1, 2}, w_g, w_b ∈ {−2 … 2}, not all zero: 74 spaces.
COLOUR_GRID = tuple(w for w in itertools.product(range(3), range(-2, 3), range(-2, 3)) if any(w))
#: 8-bit value at and above which a channel is treated as clipped.
CLIP_LEVEL = 254.0
#: The kurtosis colour searches (the extractor's and the tracker's) also leave out pixels with
#: a channel at or above this level: a JPEG-compressed clipped core sits at 251–255 with
#: smeared green and blue (evidence at `cslx.segmentation.search.SEARCH_CLIP_LEVEL` and
#: `cslx.runtime.stripe_colour`).
SEARCH_CLIP_LEVEL = 240.0
#: The kurtosis search scores every SEARCH_STRIDE-th column (row) of the frame.
SEARCH_STRIDE = 8
#: Steger σ ceiling (px) up to 480 px frames; above, ×min(H, W)/480 (the stripe's width in
#: px grows with magnification; evidence at `cslx.segmentation.robust.SIGMA_MAX`).
SIGMA_MAX = 6.0


class Stripe(enum.Enum):
    """One laser stripe of the cross.

    `H`, the horizontal stripe, crosses the followed weld: it is found per image column (its
    centre is a row, searched along axis 0 of an (H, W) image) and belongs to laser plane 0.
    `V`, the vertical stripe, runs along the weld: found per image row (a column, searched
    along axis 1) and belongs to plane 1. In the robot frame the horizontal stripe runs along
    y_r and the vertical one along x_r.
    """

    H = "h"
    V = "v"

    @property
    def axis(self) -> int:
        """The image axis the centre is searched along (0: rows, per column; 1: columns)."""
        return 0 if self is Stripe.H else 1

    @property
    def plane(self) -> int:
        """Index of this stripe's laser plane in `Sensor.planes` (the calibration file)."""
        return 0 if self is Stripe.H else 1

    @property
    def robot_axis(self) -> int:
        """The robot-frame axis the stripe runs along on the wall (1: y_r, 0: x_r)."""
        return 1 if self is Stripe.H else 0

    @property
    def label(self) -> str:
        return "horizontal" if self is Stripe.H else "vertical"

    @classmethod
    def parse(cls, value: Stripe | str | int) -> Stripe:
        """A `Stripe` from itself, "h"/"v", "horizontal"/"vertical", or the axis 0/1."""
        if isinstance(value, Stripe):
            return value
        if isinstance(value, int) and value in (0, 1):
            return cls.H if value == 0 else cls.V
        text = str(value).strip().lower()
        if text in ("h", "horizontal"):
            return cls.H
        if text in ("v", "vertical"):
            return cls.V
        raise ValueError(f"unknown stripe {value!r}: use 'h' (horizontal) or 'v' (vertical)")


@dataclasses.dataclass(frozen=True)
class Motion:
    """The robot's nominal motion: `speed_mm_s` along the weld, frames at `fps`."""

    speed_mm_s: float = 30.0
    fps: float = 20.0

    @property
    def step_mm(self) -> float:
        """Nominal travel per frame (1.5 mm at 30 mm/s and 20 fps)."""
        return self.speed_mm_s / self.fps


@dataclasses.dataclass(frozen=True)
class Rig:
    """Geometry of the default rig that other settings derive from (mm).

    lookahead_mm: x_r where the horizontal stripe meets the wall, ahead of the robot's
        reference point (the weld line's reference abscissa x_ref).
    standoff_mm: camera to wall along the optical axis.
    """

    lookahead_mm: float = 150.0
    standoff_mm: float = 230.0


MOTION = Motion()
RIG = Rig()
