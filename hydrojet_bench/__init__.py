"""HydroJet Bench: kinematic models, drivers and online disturbance estimation for soft
continuum robots (Campisano et al., RA-L 2020).

The analysis commands are functions here too, for notebooks and scripts (`hydrojet_bench.api`):
``load``, ``calibrate``, ``compare``, ``diagnose``, ``replay`` and ``study``, each returning a
typed result with ``to_pandas()`` and ``plot()``.
"""

import importlib

__version__ = "0.1.0"

API = ("load", "calibrate", "compare", "diagnose", "replay", "study")
__all__ = ["__version__", *API]


def __getattr__(name: str):
    # Imported on first use, by name: the command line and the bench import this package
    # for its version, and should neither pay for the analyses nor, for the layer rules,
    # depend on them.
    if name in API:
        return getattr(importlib.import_module(f"{__name__}.api"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
