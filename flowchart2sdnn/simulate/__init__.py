"""The chart simulated as it is written: the continuous fine-step oracle (:mod:`.continuous`), the virtual test
bench (:mod:`.excitation`: APRBS + relay, noise) and the simulation behind `sdnn simulate` (:mod:`.run`).

Layer 4.5: over the compiler and the network, under identify (which measures the discretization floor of a
fitted chart with the oracle); the oracle itself reads only the chart.
"""
