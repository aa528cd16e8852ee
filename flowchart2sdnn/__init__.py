"""flowchart2sdnn: grey-box identification of mechatronic systems.

A continuous signal flow chart (YAML) is linted, compiled into a structured General Dynamic Neural Network
whose weights are physical parameters, and identified from measured data with Levenberg-Marquardt + RTRL.
"""

__version__ = "0.1.0"

__all__ = ["__version__"]
