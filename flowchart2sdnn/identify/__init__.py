"""Identification: fit a chart to measured data (offline LM, multi-start, quasi-online)."""
