"""Parameter fitting: bounds transform, Levenberg-Marquardt, covariance, multistart and the fit result.

Generic numerics: the trainer sees a residual/Jacobian callback, never a network.
"""
