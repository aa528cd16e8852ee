"""Parameter fitting: bounds transform, Levenberg-Marquardt, covariance and multistart.

Layer 2, generic numerics: the trainer sees a residual/Jacobian callback, never a network (imports nothing of
ours).
"""
