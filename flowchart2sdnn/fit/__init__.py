"""Parameter fitting: bounds transform, Levenberg-Marquardt, covariance and multistart.

Layer 2, generic numerics: the trainer sees a residual/Jacobian callback, never a network; imports nothing but
numpy, scipy and itself. The damping schedule (:mod:`.damping`) is plain Python that the quasi-online kernel
in identify/ compiles with numba.
"""
