"""One script per table or figure of the paper (and beyond), each writing results/<name>.*.

Run a script as a module from the repository root, e.g.
``python -m experiments.table6_segmentation``; `experiments.common` holds the helpers they
share (rendered frames, timing, provenance).

The experiments are entry points: importing this package sets the process-wide settings
every script wants (`cslx.environment.configure`: single-threaded BLAS — OpenBLAS's threaded
Cholesky stalls MED on a loaded 2-core machine — and a quiet CPU start) before NumPy or JAX
load in the script.
"""

from cslx.environment import configure

configure()
