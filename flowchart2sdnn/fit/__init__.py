"""Parameter fitting: bounds transform, Levenberg-Marquardt, covariance, multistart and the fit result.

Generic numerics: the trainer sees a residual/Jacobian callback, never a network. Layer: imports nothing but
numpy, scipy and itself. The damping schedule (:mod:`.damping`) is plain Python that the quasi-online kernel
in identify/ compiles with numba.
"""
