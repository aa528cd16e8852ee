"""The network file and its runtime (simulation and RTRL Jacobian).

Layer 3: imports only :mod:`flowchart2sdnn.expr`, :mod:`flowchart2sdnn.errors` and itself (never the chart, the
compiler, fit/, identify/ or diagnose/); trainers build on it. The one simulation step and the one RTRL step of
every kernel, offline and quasi-online, are in :mod:`.kernels`.
"""
