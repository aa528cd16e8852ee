"""Analyses of a chart: its graph, loops and lint checks.

Layer 3: imports the chart and the layers below it, never the network or anything above.
"""
