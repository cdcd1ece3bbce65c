"""One script per table or figure of the paper (and beyond), each writing results/<name>.*.

Run a script as a module from the repository root, e.g.
``python -m experiments.table6_segmentation``; `experiments.common` holds the helpers they
share (rendered frames, timing, provenance).
"""
