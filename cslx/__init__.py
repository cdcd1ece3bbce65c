"""cslx: cross structured-light stripe sensing for weld-tracking robots, in JAX.

A reproduction and extension of Zhang et al., "A Cross Structured Light Sensor and Stripe
Segmentation Method for Visual Tracking of a Wall Climbing Robot", Sensors 15 (2015).

The subpackages are the architecture, in pipeline order:

- `cslx.sensor`: camera model, laser planes, triangulation, the calibration file;
- `cslx.segmentation`: colour space, MED, Steger centres, the Table 6 baselines;
- `cslx.calibration`: corners, Zhang + Levenberg–Marquardt, laser planes, robot frame;
- `cslx.runtime`: the jitted per-frame pipeline, weld features, tracker, robot link;
- `cslx.sim`: the renderer with exact ground truth, the robot simulator, the closed loop;
- `cslx.cli`: the `cslx` command line.

`cslx.config` holds every shared setting. Importing cslx is free of side effects and does
not import JAX; the names below load their subpackage on first use. Entry points that want
single-threaded BLAS or a compile cache call `cslx.environment.configure()` explicitly.
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

_LAZY = {
    "sensor": (
        "Camera",
        "CalibrationError",
        "Sensor",
        "default_sensor",
        "load_sensor",
        "save_sensor",
        "triangulate",
        "distort",
        "undistort",
        "project",
        "pixel_to_ray",
    ),
    "segmentation": (
        "Centres",
        "MEDResult",
        "METHODS",
        "extract",
        "centres_to_pixels",
        "stripe_errors",
        "monochrome",
        "search_space",
        "optimise_weights",
        "parse_space",
        "kurtosis_objective",
        "med_apply",
        "med_objective",
        "steger_centres",
        "steger_cross",
        "sigma_for_width",
    ),
    "runtime": ("WeldConfig", "WeldFeature", "stripe_feature", "weld_features", "Tracker"),
}
_OWNER = {name: pkg for pkg, names in _LAZY.items() for name in names}
_SUBPACKAGES = (
    "calibration",
    "cli",
    "config",
    "environment",
    "provenance",
    "runtime",
    "segmentation",
    "sensor",
    "sim",
)

__all__ = sorted(_OWNER)


def __getattr__(name: str):
    if name in _OWNER:
        return getattr(importlib.import_module(f"{__name__}.{_OWNER[name]}"), name)
    if name in _SUBPACKAGES:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted({*globals(), *_OWNER, *_SUBPACKAGES})
