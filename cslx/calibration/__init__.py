"""Calibration of the camera, the laser planes and the robot frame (paper section 2.3).

- `corners`: chessboard corners and the board's model points.
- `zhang`: Zhang's closed form (eqs. (5)–(7)): homographies, intrinsics, poses.
- `camera`: Levenberg–Marquardt refinement of intrinsics, distortion and poses.
- `planes`: stripe points lifted onto the boards, laser planes fitted robustly (Figs. 4–5).
- `robot_frame`: the camera-to-robot rigid transform.
- `joint`: one joint refinement of camera, poses and planes (beyond the paper).
- `pipeline`: `calibrate_sensor`, the whole calibration in one call (corners → camera →
  planes → robot frame → `Sensor` + report), used by `cslx calibrate`, the demo and Table 5.
"""

from .camera import CameraCalibration as CameraCalibration
from .camera import board_planes as board_planes
from .camera import calibrate_camera as calibrate_camera
from .corners import board_points as board_points
from .corners import detect_corners as detect_corners
from .joint import JointCalibration as JointCalibration
from .joint import refine_sensor as refine_sensor
from .pipeline import SensorCalibration as SensorCalibration
from .pipeline import calibrate_sensor as calibrate_sensor
from .pipeline import read_image as read_image
from .planes import PlaneCalibration as PlaneCalibration
from .planes import PlaneFit as PlaneFit
from .planes import PlaneGates as PlaneGates
from .planes import board_mask as board_mask
from .planes import calibrate_planes as calibrate_planes
from .planes import edge_crossings as edge_crossings
from .planes import fit_plane as fit_plane
from .planes import laser_centres as laser_centres
from .planes import lift_to_board as lift_to_board
from .planes import on_board as on_board
from .planes import stripe_pixels as stripe_pixels
from .robot_frame import fit_rigid as fit_rigid
from .zhang import homography as homography
from .zhang import intrinsics_from_homographies as intrinsics_from_homographies
from .zhang import pose_from_homography as pose_from_homography
from .zhang import rodrigues as rodrigues
from .zhang import rotation_to_rvec as rotation_to_rvec
from .zhang import zhang_init as zhang_init

__all__ = [
    "board_points",
    "detect_corners",
    "rodrigues",
    "rotation_to_rvec",
    "homography",
    "intrinsics_from_homographies",
    "pose_from_homography",
    "zhang_init",
    "CameraCalibration",
    "board_planes",
    "calibrate_camera",
    "PlaneFit",
    "PlaneCalibration",
    "PlaneGates",
    "SensorCalibration",
    "calibrate_sensor",
    "read_image",
    "fit_plane",
    "laser_centres",
    "lift_to_board",
    "board_mask",
    "on_board",
    "stripe_pixels",
    "calibrate_planes",
    "edge_crossings",
    "fit_rigid",
    "JointCalibration",
    "refine_sensor",
]
