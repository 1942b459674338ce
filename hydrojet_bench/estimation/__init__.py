"""Estimation: the online disturbance estimator of the paper (eq. 4)."""

from .online import EstimateStep, OnlineDisturbanceEstimator, OnlineSettings

__all__ = ["EstimateStep", "OnlineDisturbanceEstimator", "OnlineSettings"]
