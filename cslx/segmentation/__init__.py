"""Stripe segmentation: colour space → MED → Steger centres, and the paper's baselines.

- `colour`: the kurtosis-maximising monochromatic space (eqs. (9)–(12), (19)).
- `med`: minimum entropy deconvolution as an optimistix fixed point (eqs. (18), (22)–(26)).
- `steger`: sub-pixel ridge centres (Steger 1998), batched.
- `baselines`: CM / LA / QA / AA of the paper's Table 6.
- `ridges`, `robust`: the robust detector of issue 11 (method "linked"): candidate ridges
  linked into one path, clipped cores, width-aware σ, a predicted std per centre.
- `interface`: `extract`, one interface over every method; `metrics`: the error metrics
  of docs/metrics.md.
- `shard`: the same over frame batches and devices.
"""

from . import med as med
from .baselines import aa as aa
from .baselines import cm as cm
from .baselines import column_peaks as column_peaks
from .baselines import la as la
from .baselines import qa as qa
from .baselines import split_and_merge as split_and_merge
from .colour import CANDIDATES as CANDIDATES
from .colour import DEFAULT_FORM as DEFAULT_FORM
from .colour import NAMED_SPACES as NAMED_SPACES
from .colour import column_kurtosis as column_kurtosis
from .colour import kurtosis_objective as kurtosis_objective
from .colour import monochrome as monochrome
from .colour import optimise_weights as optimise_weights
from .colour import parse_space as parse_space
from .colour import search_space as search_space
from .interface import DEFAULT_SIGMA as DEFAULT_SIGMA
from .interface import METHODS as METHODS
from .interface import STRIPES as STRIPES
from .interface import centres_to_pixels as centres_to_pixels
from .interface import extract as extract
from .interface import monochrome_for as monochrome_for
from .med import MEDResult as MEDResult
from .med import default_filter_length as default_filter_length
from .med import initial_filter as initial_filter
from .med import med_apply as med_apply
from .med import med_objective as med_objective
from .med import med_prepare as med_prepare
from .med import med_update as med_update
from .metrics import GROSS_MM as GROSS_MM
from .metrics import stripe_errors as stripe_errors
from .metrics import stripe_point_errors as stripe_point_errors
from .ridges import LinkParams as LinkParams
from .ridges import linked_centres as linked_centres
from .robust import linked_extract as linked_extract
from .steger import Centres as Centres
from .steger import gaussian_derivative as gaussian_derivative
from .steger import sigma_for_width as sigma_for_width
from .steger import steger_centres as steger_centres
from .steger import steger_cross as steger_cross

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
