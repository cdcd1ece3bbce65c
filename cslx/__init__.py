"""cslx: cross structured-light stripe sensing for weld-tracking robots, in JAX.

A reproduction and extension of Zhang et al., "A Cross Structured Light Sensor and Stripe
Segmentation Method for Visual Tracking of a Wall Climbing Robot", Sensors 15 (2015).
"""

from .camera import Camera as Camera
from .camera import distort as distort
from .camera import pixel_to_ray as pixel_to_ray
from .camera import project as project
from .camera import undistort as undistort
from .sensor import CalibrationError as CalibrationError
from .sensor import Sensor as Sensor
from .sensor import default_sensor as default_sensor
from .sensor import load_sensor as load_sensor
from .sensor import save_sensor as save_sensor
from .sensor import triangulate as triangulate

__version__ = "0.1.0"
