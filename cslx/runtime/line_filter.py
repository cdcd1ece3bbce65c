"""The tracker's weld-line filter: Kalman filter over (offset e, heading θ), re-acquiring gates.

The model, the prediction from odometry, the update with the horizontal stripe's bead centre and
the gating that re-acquires are described in `cslx.runtime.tracker`'s module docstring; this
module holds the filter and its tuning (`KalmanConfig`) so that the tracker stays short.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

__all__ = ["KalmanConfig", "WeldLineFilter"]


@dataclasses.dataclass(frozen=True)
class KalmanConfig:
    """Tuning of the weld-line filter (module docstring). mm, rad, frames."""

    q_offset: float = 0.08  # mm per √mm travelled
    q_heading: float = 0.002  # rad per √mm travelled
    q_floor: float = 1e-4  # mm², rad² per frame (a robot at rest drifts a little too)
    sigma_meas: float = 0.35  # mm, at confidence 1
    init_offset_std: float = 2.0  # mm
    init_heading_std: float = math.radians(10.0)
    gate: float = 4.0  # innovation standard deviations
    reset_after: int = 3  # mutually consistent rejected measurements in a row → restart
    consistent_mm: float = 1.0  # half their spread (max − min) at x_ref, mm
    give_up_after: int = 8  # rejected measurements in a row that restart it regardless
    heading_valid_deg: float = 3.0
    decay: float = 0.85  # confidence per frame without a bead
    junction_window: int = 10
    junction_tol_mm: float = 6.0
    # A crossing bead lower than this is not a weld: on rendered straight-weld frames the
    # full-frame pass showed 0.6 mm, 13 mm wide bumps on the bare plate (segmentation
    # artefacts) that the detector took for a crossing bead; weld reinforcement is 1–3 mm.
    junction_min_height_mm: float = 0.8
    # a bead whose width differs from the median of the last `width_memory` accepted ones by
    # u·width_tol of it (|u| > 1) has its confidence divided by u²: in sunlight a glint that
    # hides a flank makes the bead look narrower or merges it with the plate (widths of 10 to
    # 34 mm for a 14 mm bead at dev seed 1201), and those are the frames whose position is off
    width_tol: float = 0.2
    width_memory: int = 20
    # fuse the heading the vertical stripe sees (`weld.heading_from_vertical`). Off: along the
    # bead's flank (dev seed 1201, odometry) the heading error went 0.51° → 1.34° (clean),
    # 0.60° → 1.70° (sun); beside the weld it never sees the weld's direction
    use_vertical_heading: bool = False
    sigma_heading_floor_deg: float = 0.3  # its standard deviation at least this


class WeldLineFilter:
    """Kalman filter over (offset e mm, heading θ rad); see the module docstring."""

    def __init__(self, config: KalmanConfig, x_ref: float):
        self.c = config
        self.x_ref = x_ref
        self.reset()

    def reset(self) -> None:
        self.x: np.ndarray | None = None
        self.P = np.zeros((2, 2))
        self.rejected = 0
        self.restarts = 0
        self.pending: list[np.ndarray] = []  # rejected centres (x_r, y_r), current frame

    @staticmethod
    def _carry(p: np.ndarray, d: float, delta: float) -> np.ndarray:
        """A wall point (x_r, y_r) seen from the robot after it moved d mm and turned δ."""
        x, y = p[0] - d, p[1]
        c, s = np.cos(delta), np.sin(delta)
        return np.array([c * x + s * y, -s * x + c * y])

    @property
    def initialised(self) -> bool:
        return self.x is not None

    def predict(self, d: float, delta: float) -> None:
        self.pending = [self._carry(p, d, delta) for p in self.pending]
        if self.x is None:
            return
        c = self.c
        F = np.array([[1.0, d], [0.0, 1.0]])
        self.x = F @ self.x + np.array([-self.x_ref * delta, -delta])
        Q = np.diag([c.q_offset**2, c.q_heading**2]) * abs(d) + c.q_floor * np.eye(2)
        self.P = F @ self.P @ F.T + Q

    def start(self, y: float, theta: float = 0.0) -> None:
        c = self.c
        self.x = np.array([y, theta])
        self.P = np.diag([c.init_offset_std**2, c.init_heading_std**2])
        self.rejected = 0
        self.pending = []

    def _reacquire(self) -> bool:
        """Restart at the rejected centres if the last `reset_after` agree (docstring)."""
        c = self.c
        recent = np.array(self.pending[-c.reset_after :])
        theta = float(self.x[1]) if self.x is not None else 0.0
        at_ref = recent[:, 1] - np.tan(theta) * (recent[:, 0] - self.x_ref)
        agree = len(recent) >= c.reset_after and np.ptp(at_ref) <= 2.0 * c.consistent_mm
        if agree or self.rejected >= c.give_up_after:
            y = float(np.mean(at_ref)) if agree else float(at_ref[-1])
            self.start(y, theta)
            self.restarts += 1
            return True
        return False

    def update_heading(self, theta: float, sd: float) -> bool:
        """Fuse a direct heading measurement (rad, its standard deviation rad); gated."""
        if self.x is None:
            return False
        R = max(sd, np.radians(self.c.sigma_heading_floor_deg)) ** 2
        H = np.array([0.0, 1.0])
        S = self.P[1, 1] + R
        nu = theta - self.x[1]
        if nu * nu > self.c.gate**2 * S:
            return False
        K = self.P @ H / S
        self.x = self.x + K * nu
        self.P = (np.eye(2) - np.outer(K, H)) @ self.P
        self.P = 0.5 * (self.P + self.P.T)
        return True

    def update(self, x_c: float, y_c: float, confidence: float) -> bool:
        """Fuse one bead centre; False if gated out (the filter may restart)."""
        c = self.c
        if self.x is None:
            self.start(y_c)
            return True
        H = np.array([1.0, x_c - self.x_ref])
        R = c.sigma_meas**2 / max(confidence, 0.05)
        S = H @ self.P @ H + R
        nu = y_c - H @ self.x
        if nu * nu > c.gate**2 * S:
            self.rejected += 1
            self.pending.append(np.array([x_c, y_c], float))
            return self._reacquire()
        K = self.P @ H / S
        self.x = self.x + K * nu
        self.P = (np.eye(2) - np.outer(K, H)) @ self.P
        self.P = 0.5 * (self.P + self.P.T)
        self.rejected = 0
        self.pending = []
        return True
