"""The quasi-online fit (the paper's sliding-window LM): :mod:`.run` (options, the run, its result) over the
numba loop of :mod:`.kernel` (state, per-sample loop, trial mode) and :mod:`.window` (the window numerics).

The package's names are reached through :mod:`flowchart2sdnn.identify`; this file imports nothing.
"""
