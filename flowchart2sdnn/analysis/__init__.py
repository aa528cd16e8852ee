"""Analyses of a chart: its graph, loops and lint checks."""
