"""Estimation: calibration (paper eq. 24), the online disturbance estimator (eq. 4) and
the path predictor that runs both along a path (`estimation.path`)."""

from .online import EstimateStep, OnlineDisturbanceEstimator, OnlineSettings

__all__ = ["EstimateStep", "OnlineDisturbanceEstimator", "OnlineSettings"]
