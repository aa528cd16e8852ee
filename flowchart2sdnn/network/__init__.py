"""The network file and its runtime (simulation and RTRL Jacobian)."""
