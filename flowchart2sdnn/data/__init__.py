"""Measured data in and out: CSV files read safely (:mod:`.csvdata`).

Layer 2: imports only errors and atomic writes. Simulated data come from :mod:`flowchart2sdnn.simulate`.
"""
