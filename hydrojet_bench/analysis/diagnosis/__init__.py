"""Which physical effect is the model missing? Cross-validated calibration of the
baseline model and of the baseline plus each candidate effect, against the noise floor
measured from the data itself. `diagnose` is the entry point (see `engine`)."""

from .engine import (NONE, UNDECIDED, UNEXPLAINED, CandidateResult, Diagnosis, DiagnosisSettings, default_candidates,
                     diagnose)
from .noise import NoiseFloor, estimate_noise_floor
from .split import Split, split_session

__all__ = ["NONE", "UNDECIDED", "UNEXPLAINED", "CandidateResult", "Diagnosis", "DiagnosisSettings", "NoiseFloor",
           "Split", "default_candidates", "diagnose", "estimate_noise_floor", "split_session"]
