"""The simulation laboratory: rendered scenes with exact ground truth, and the closed loop.

- `scene`: the wall, weld beads, robot poses, ray casting and the exact stripe truth.
- `shade`: lighting and nuisances (sunlight, glints, shadows, speckle, noise, clipping).
- `render`: frames and datasets (the rendered-data contract of docs/contracts.md).
- `video`: a robot pass along a weld; `boards`: calibration captures.
- `robot`: a robot simulator on a pseudo-terminal; `closed_loop`: tracker + controller +
  simulated robot through a T-junction.
"""

from .boards import render_calibration as render_calibration
from .render import HARD_NUISANCES as HARD_NUISANCES
from .render import LASER_RGB as LASER_RGB
from .render import NUISANCE_NAMES as NUISANCE_NAMES
from .render import NUISANCES as NUISANCES
from .render import load_dataset as load_dataset
from .render import make_world as make_world
from .render import random_pose as random_pose
from .render import random_world as random_world
from .render import render_dataset as render_dataset
from .render import render_frame as render_frame
from .render import render_image as render_image
from .render import write_dataset as write_dataset
from .scene import RobotPose as RobotPose
from .scene import World as World
from .scene import camera_to_world as camera_to_world
from .scene import stripe_truth as stripe_truth
from .shade import Nuisance as Nuisance
from .truth import true_weld_line as true_weld_line
from .video import render_video as render_video
from .video import video_path as video_path

__all__ = [
    "World",
    "RobotPose",
    "camera_to_world",
    "stripe_truth",
    "Nuisance",
    "NUISANCES",
    "HARD_NUISANCES",
    "NUISANCE_NAMES",
    "LASER_RGB",
    "make_world",
    "random_world",
    "random_pose",
    "render_image",
    "render_frame",
    "render_dataset",
    "write_dataset",
    "load_dataset",
    "true_weld_line",
    "video_path",
    "render_video",
    "render_calibration",
]
