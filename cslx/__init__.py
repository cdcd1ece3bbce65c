"""cslx: cross structured-light stripe sensing for weld-tracking robots, in JAX.

A reproduction and extension of Zhang et al., "A Cross Structured Light Sensor and Stripe
Segmentation Method for Visual Tracking of a Wall Climbing Robot", Sensors 15 (2015).

One module per stage: `camera` (pinhole + Brown–Conrady), `sensor` (laser planes,
triangulation, calibration file), `colour` (kurtosis colour space), `med` (minimum entropy
deconvolution), `steger` (sub-pixel ridge centres), `baselines` (CM / LA / QA / AA),
`segment` (one interface over all methods, metrics), `calibration` (Zhang + LM, laser
planes, robot frame), `weld` (bead and junction features), `pipeline` (the jitted per-frame
function), `tracker` (the runtime object), `robot` (serial protocol, link, controller,
simulator), `synth` (the renderer with exact ground truth), `shard` (multi-device batches).
Heavy modules (`synth`, `calibration`, `tracker`, `robot`) are imported on demand.

Importing cslx limits OpenBLAS to one thread (see `cslx._threads`; CSLX_BLAS_THREADS).
"""

from ._threads import limit_blas_threads as _limit_blas_threads
from .camera import Camera as Camera
from .camera import distort as distort
from .camera import pixel_to_ray as pixel_to_ray
from .camera import project as project
from .camera import undistort as undistort
from .colour import CANDIDATES as CANDIDATES
from .colour import NAMED_SPACES as NAMED_SPACES
from .colour import kurtosis_objective as kurtosis_objective
from .colour import monochrome as monochrome
from .colour import optimise_weights as optimise_weights
from .colour import parse_space as parse_space
from .colour import search_space as search_space
from .med import MEDResult as MEDResult
from .med import med as med
from .med import med_apply as med_apply
from .med import med_objective as med_objective
from .segment import METHODS as METHODS
from .segment import centres_to_pixels as centres_to_pixels
from .segment import extract as extract
from .segment import stripe_errors as stripe_errors
from .sensor import CalibrationError as CalibrationError
from .sensor import Sensor as Sensor
from .sensor import default_sensor as default_sensor
from .sensor import load_sensor as load_sensor
from .sensor import save_sensor as save_sensor
from .sensor import triangulate as triangulate
from .steger import Centres as Centres
from .steger import sigma_for_width as sigma_for_width
from .steger import steger_centres as steger_centres
from .steger import steger_cross as steger_cross
from .weld import WeldConfig as WeldConfig
from .weld import WeldFeature as WeldFeature
from .weld import stripe_feature as stripe_feature
from .weld import weld_features as weld_features

__version__ = "0.1.0"

_limit_blas_threads()
