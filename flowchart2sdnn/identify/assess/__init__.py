"""What a fit's numbers are worth: the discretization floor (:mod:`.floor`) and its bias on the parameters
(:mod:`.floorbias`), the evidence of a fit (:mod:`.evidence`: intervals, bounds, stability, excitation), the
records' measurement noise every "x the noise" rule reads (:mod:`.noise`) and the residual's lag-0 correlation
with a held input (:mod:`.lagzero`).

The package's names are reached through :mod:`flowchart2sdnn.identify`; this file imports nothing.
"""
