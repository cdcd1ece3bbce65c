"""Robot runtime shell: binary protocol, serial link with watchdog, path controller, simulator.

Thin and numerics-free (STYLE.md): `serial` is imported lazily inside `RobotLink`.
The protocol is specified in PROTOCOL.md beside this file.
"""

from .controller import Command as Command
from .controller import ControllerConfig as ControllerConfig
from .controller import PathController as PathController
from .controller import State as State
from .link import RobotLink as RobotLink
from .protocol import Ack as Ack
from .protocol import Decoder as Decoder
from .protocol import Heartbeat as Heartbeat
from .protocol import Observation as Observation
from .protocol import RobotState as RobotState
from .protocol import Stop as Stop
from .protocol import StopReason as StopReason
from .protocol import VelocityCommand as VelocityCommand
from .protocol import encode as encode
from .simulator import RobotSimulator as RobotSimulator
from .simulator import SimulatorConfig as SimulatorConfig
