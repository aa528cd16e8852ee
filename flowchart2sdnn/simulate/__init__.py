"""The chart simulated as it is written: the continuous fine-step oracle (:mod:`.continuous`), the virtual test
bench (:mod:`.excitation`: APRBS + relay, noise) and the simulation behind `sdnn simulate` (:mod:`.run`).

Layer 6: over identify (it reads result files); nothing of the identification core imports it.
"""
