"""The robot runtime: the jitted per-frame pipeline, the tracker and the serial link.

Nothing here imports the simulation (`cslx.sim`): a robot without a renderer runs it.

- `pipeline`: one frame → stripe centres → 3-D profiles → weld features (jit).
- `weld`: bead and T-junction features of a 3-D stripe profile.
- `tracker`: the runtime object: offset and heading of the weld line, Kalman-filtered.
- `protocol`, `link`, `controller`: the binary serial protocol (PROTOCOL.md), the pyserial
  link with its watchdog, and the path controller.
- `loop`: the one per-frame loop (tracker → controller → link, time, odometry, the log)
  that `cslx track` and the closed-loop simulation both run.
"""

from __future__ import annotations

from ..lazy import lazy_attributes

#: Public name → the submodule that defines it, imported on first use (`__getattr__`):
#: importing the package loads no submodule, so the robot's start-up imports only what it
#: uses (issue 13).
_OWNER = {
    "process_batch": "batch",
    "Command": "controller",
    "ControllerConfig": "controller",
    "PathController": "controller",
    "State": "controller",
    "wheel_speeds": "controller",
    "RobotLink": "link",
    "LoopConfig": "loop",
    "TrackingLoop": "loop",
    "TrackLog": "loop",
    "odometry_between": "loop",
    "SUMMARY_FIELDS": "pipeline",
    "FrameResult": "pipeline",
    "PipelineConfig": "pipeline",
    "PipelineState": "pipeline",
    "frame_summary": "pipeline",
    "init_state": "pipeline",
    "process_frame": "pipeline",
    "Ack": "protocol",
    "Decoder": "protocol",
    "Heartbeat": "protocol",
    "ProtocolError": "protocol",
    "RobotState": "protocol",
    "Stop": "protocol",
    "StopReason": "protocol",
    "VelocityCommand": "protocol",
    "encode": "protocol",
    "LOG_FIELDS": "tracker",
    "FrameGates": "tracker",
    "KalmanConfig": "tracker",
    "Tracker": "tracker",
    "WeldConfig": "weld",
    "WeldFeature": "weld",
    "WeldLine": "weld",
    "plate_fit": "weld",
    "stripe_feature": "weld",
    "weld_features": "weld",
    "weld_line_from_features": "weld",
}

__all__ = [
    "FrameResult",
    "PipelineConfig",
    "PipelineState",
    "SUMMARY_FIELDS",
    "frame_summary",
    "init_state",
    "process_batch",
    "process_frame",
    "WeldConfig",
    "WeldFeature",
    "WeldLine",
    "plate_fit",
    "stripe_feature",
    "weld_features",
    "weld_line_from_features",
    "FrameGates",
    "KalmanConfig",
    "Tracker",
    "LOG_FIELDS",
    "ControllerConfig",
    "Command",
    "PathController",
    "State",
    "wheel_speeds",
    "RobotLink",
    "LoopConfig",
    "TrackingLoop",
    "TrackLog",
    "odometry_between",
    "Ack",
    "Decoder",
    "Heartbeat",
    "ProtocolError",
    "RobotState",
    "Stop",
    "StopReason",
    "VelocityCommand",
    "encode",
]


__getattr__, __dir__ = lazy_attributes(__name__, globals(), _OWNER)
