"""Data in and out: measured CSV files read safely (:mod:`.csvdata`), simulated data (:mod:`.continuous`)."""
