"""Stripe segmentation: colour space → MED → Steger centres, and the paper's baselines.

- `colour`: the kurtosis-maximising monochromatic space (eqs. (9)–(12), (19)).
- `med`: minimum entropy deconvolution as an optimistix fixed point (eqs. (18), (22)–(26)).
- `steger`: sub-pixel ridge centres (Steger 1998), batched.
- `baselines`: CM / LA / QA / AA of the paper's Table 6.
- `ridges`, `robust`: the robust detector of issue 11 (method "linked"): candidate ridges
  linked into one path, clipped cores, width-aware σ, a predicted std per centre.
  `presence`: its test that a stripe is there at all (laser off: no centres); `crossing`:
  the centres a turned cross's other stripe or the image border make unmeasurable; `ends`:
  the first pass's tail past a turned stripe's end inside the frame.
- `interface`: `extract`, one interface over every method; `metrics`: the error metrics
  of docs/metrics.md.
- `shard`: the same over frame batches and devices.
"""

from __future__ import annotations

from ..lazy import lazy_attributes

#: Public name → the submodule that defines it, imported on first use (`__getattr__`):
#: importing the package loads no submodule, so the robot's start-up imports only what it
#: uses (issue 13).
_OWNER = {
    "med": None,  # the submodule itself
    "aa": "baselines",
    "cm": "baselines",
    "column_peaks": "baselines",
    "la": "baselines",
    "qa": "baselines",
    "split_and_merge": "baselines",
    "CANDIDATES": "colour",
    "DEFAULT_FORM": "colour",
    "NAMED_SPACES": "colour",
    "column_kurtosis": "colour",
    "kurtosis_objective": "colour",
    "monochrome": "colour",
    "optimise_weights": "colour",
    "parse_space": "colour",
    "search_space": "colour",
    "DEFAULT_SIGMA": "interface",
    "METHODS": "interface",
    "STRIPES": "interface",
    "centres_to_pixels": "interface",
    "extract": "interface",
    "monochrome_for": "interface",
    "MEDResult": "med",
    "default_filter_length": "med",
    "initial_filter": "med",
    "med_apply": "med",
    "med_objective": "med",
    "med_prepare": "med",
    "med_update": "med",
    "GROSS_MM": "metrics",
    "stripe_errors": "metrics",
    "stripe_point_errors": "metrics",
    "LinkParams": "ridges",
    "linked_centres": "ridges",
    "linked_extract": "robust",
    "Centres": "steger",
    "gaussian_derivative": "steger",
    "sigma_for_width": "steger",
    "steger_centres": "steger",
    "steger_cross": "steger",
}

__all__ = [
    "med",
    "CANDIDATES",
    "NAMED_SPACES",
    "DEFAULT_FORM",
    "monochrome",
    "column_kurtosis",
    "kurtosis_objective",
    "search_space",
    "optimise_weights",
    "parse_space",
    "MEDResult",
    "med_apply",
    "med_objective",
    "med_prepare",
    "med_update",
    "default_filter_length",
    "initial_filter",
    "Centres",
    "LinkParams",
    "linked_centres",
    "linked_extract",
    "gaussian_derivative",
    "sigma_for_width",
    "steger_centres",
    "steger_cross",
    "cm",
    "la",
    "qa",
    "aa",
    "column_peaks",
    "split_and_merge",
    "METHODS",
    "STRIPES",
    "DEFAULT_SIGMA",
    "GROSS_MM",
    "centres_to_pixels",
    "extract",
    "monochrome_for",
    "stripe_errors",
    "stripe_point_errors",
]


__getattr__, __dir__ = lazy_attributes(__name__, globals(), _OWNER)
