"""The sensor model: camera, laser planes, triangulation, and the calibration file.

- `camera`: pinhole + Brown–Conrady distortion (the corrected eq. (4)); undistortion as an
  optimistix fixed point.
- `rig`: the `Sensor` (camera + laser planes + camera-to-robot transform, eq. (1)) and
  triangulation (the corrected eq. (27)).
- `calibration_file`: the JSON contract (docs/contracts.md), validated on load.
"""

from .calibration_file import load_sensor as load_sensor
from .calibration_file import save_sensor as save_sensor
from .calibration_file import sensor_to_dict as sensor_to_dict
from .calibration_file import validate_calibration as validate_calibration
from .camera import Camera as Camera
from .camera import distort as distort
from .camera import normalized_to_pixel as normalized_to_pixel
from .camera import pixel_to_normalized as pixel_to_normalized
from .camera import pixel_to_ray as pixel_to_ray
from .camera import project as project
from .camera import undistort as undistort
from .rig import TABLE4_DIST as TABLE4_DIST
from .rig import TABLE4_K as TABLE4_K
from .rig import CalibrationError as CalibrationError
from .rig import Sensor as Sensor
from .rig import cross_projector_planes as cross_projector_planes
from .rig import default_mount as default_mount
from .rig import default_sensor as default_sensor
from .rig import plane_angle_deg as plane_angle_deg
from .rig import sensor_from_arrays as sensor_from_arrays
from .rig import triangulate as triangulate

__all__ = [
    "Camera",
    "distort",
    "undistort",
    "project",
    "pixel_to_normalized",
    "pixel_to_ray",
    "normalized_to_pixel",
    "CalibrationError",
    "Sensor",
    "triangulate",
    "plane_angle_deg",
    "cross_projector_planes",
    "default_mount",
    "default_sensor",
    "sensor_from_arrays",
    "TABLE4_K",
    "TABLE4_DIST",
    "validate_calibration",
    "load_sensor",
    "sensor_to_dict",
    "save_sensor",
]
