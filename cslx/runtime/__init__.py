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

from .batch import process_batch as process_batch
from .controller import Command as Command
from .controller import ControllerConfig as ControllerConfig
from .controller import PathController as PathController
from .controller import State as State
from .controller import wheel_speeds as wheel_speeds
from .link import RobotLink as RobotLink
from .loop import LoopConfig as LoopConfig
from .loop import TrackingLoop as TrackingLoop
from .loop import TrackLog as TrackLog
from .loop import odometry_between as odometry_between
from .pipeline import SUMMARY_FIELDS as SUMMARY_FIELDS
from .pipeline import FrameResult as FrameResult
from .pipeline import PipelineConfig as PipelineConfig
from .pipeline import PipelineState as PipelineState
from .pipeline import frame_summary as frame_summary
from .pipeline import init_state as init_state
from .pipeline import process_frame as process_frame
from .protocol import Ack as Ack
from .protocol import Decoder as Decoder
from .protocol import Heartbeat as Heartbeat
from .protocol import ProtocolError as ProtocolError
from .protocol import RobotState as RobotState
from .protocol import Stop as Stop
from .protocol import StopReason as StopReason
from .protocol import VelocityCommand as VelocityCommand
from .protocol import encode as encode
from .tracker import LOG_FIELDS as LOG_FIELDS
from .tracker import FrameGates as FrameGates
from .tracker import KalmanConfig as KalmanConfig
from .tracker import Tracker as Tracker
from .weld import WeldConfig as WeldConfig
from .weld import WeldFeature as WeldFeature
from .weld import WeldLine as WeldLine
from .weld import plate_fit as plate_fit
from .weld import stripe_feature as stripe_feature
from .weld import weld_features as weld_features
from .weld import weld_line_from_features as weld_line_from_features

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
