"""Analysis: error metrics and breakdowns comparing model predictions with measurements."""
