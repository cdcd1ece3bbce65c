"""Opt-in: a crossing bead cut by the far end of the vertical stripe's view is no sighting
(`KalmanConfig.junction_cut_margin_mm`, `Tracker._junction`)."""

import dataclasses
import math
from types import SimpleNamespace

import numpy as np

from cslx.runtime.junction_track import JunctionTrack
from cslx.runtime.line_filter import KalmanConfig
from cslx.runtime.tracker import Observation, Tracker


def _reports(x: float, width: float, margin: float, frames: int = 5) -> list[float]:
    """Reported junction x per frame for a static robot whose vertical stripe is measured from
    96.5 to 219.4 mm and sees a crossing bead at x of this width every frame."""
    c = dataclasses.replace(KalmanConfig(), junction_cut_margin_mm=margin)
    tracker = SimpleNamespace(
        kalman=c,
        _junctions=JunctionTrack(
            c.junction_window, c.junction_tol_mm, c.junction_hold, x_min_mm=150.0
        ),
    )
    xs = np.linspace(96.5, 219.4, 200)
    points_v = np.stack([xs, np.full_like(xs, -39.0)], 1)
    raw = dict(junction=1.0, v_x_mm=x, v_width_mm=width, v_height_mm=1.5)
    out = []
    for i in range(frames):
        obs = Observation(frame=i, t=0.05 * i)
        Tracker._junction(tracker, obs, raw, points_v)
        out.append(obs.junction_x_mm if obs.junction else math.nan)
    return out


def test_cut_crossing_is_not_reported():
    # the visible part of a bar whose centre lies beyond the view (7305 flank glare, frame 10)
    assert all(math.isnan(r) for r in _reports(211.0, 15.1, 1.0))
    assert _reports(211.0, 15.1, -1.0)[1] == 211.0  # without the rule: confirmed on frame 1


def test_whole_crossing_is_reported():
    # the same bar once wholly inside (far toe 2 mm before the end)
    assert _reports(208.3, 18.1, 1.0)[1:] == [208.3] * 4
