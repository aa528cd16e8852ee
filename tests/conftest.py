"""Test-wide settings."""

import os

# single-threaded BLAS, as the CLI uses (see flowchart2sdnn/cli/__init__.py): faster and steadier for our sizes
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
