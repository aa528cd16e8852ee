"""The network file and its runtime (simulation and RTRL Jacobian).

Layer 3: imports only the expression language and errors; never the chart, the compiler or a trainer.
"""
