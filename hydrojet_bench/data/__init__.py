"""Measurement data: the `Dataset` every analysis consumes, and the CSV contract.

Commands load their input through `hydrojet_bench.inputs` (`load_dataset`, or
`load_steps` for the settled steps alone), which also reads session logs; this package
knows nothing of logs (the logs package builds on it).
"""

from __future__ import annotations

from .csv_io import KNOWN_COLUMNS, OPTIONAL_COLUMNS, REQUIRED_COLUMNS, read_csv, read_csv_steps, write_csv
from .dataset import (UNUSABLE, Dataset, SampleFlag, average_quaternions, saturation_flags,
                      steps_from_runs)

__all__ = [
    "KNOWN_COLUMNS", "OPTIONAL_COLUMNS", "REQUIRED_COLUMNS", "UNUSABLE", "Dataset", "SampleFlag",
    "average_quaternions", "read_csv", "read_csv_steps", "saturation_flags", "steps_from_runs", "write_csv",
]
