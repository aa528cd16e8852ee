"""Measured data in and out: CSV files read safely (:mod:`.csvdata`: the file checked
(:mod:`.csvfile`), its rows streamed (:mod:`.csvrows`), into a :class:`~.dataset.Dataset`).

Layer 2: imports only errors and atomic writes. Simulated data come from :mod:`flowchart2sdnn.simulate`.
"""
