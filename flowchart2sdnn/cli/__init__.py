"""The `sdnn` command line: a thin click layer over the library.

Layer rule: this package is the top layer, the only place that knows click, exit codes and terminal output;
library modules never import it. :mod:`.main` holds the group and the small commands and registers the rest
(:mod:`.identify`, :mod:`.diagnose`, :mod:`.batch`, :mod:`.report`); :mod:`.options` the options every command
shares (each declared once), the error handling and the exit codes; :mod:`.order` the one argument order
(``sdnn COMMAND CHART [DATA...]``) and the older spellings it still reads; :mod:`.help` ``--help`` in sections;
:mod:`.terminal` progress and Ctrl-C.

Exit codes: 0 success, 1 a user error (bad chart, bad data, failed run; one line on stderr), 2 bad usage.
"""

from __future__ import annotations

import os

# Our matrices are small (P x P, or M x P with P ~ 10): threaded BLAS only adds contention. On a shared 2-core
# machine one J^T J took 1.6 s with default threads and 11 ms with one. Set before numpy is first imported;
# a user's own setting wins.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from .main import main  # noqa: E402 - after the thread settings

__all__ = ["main"]
