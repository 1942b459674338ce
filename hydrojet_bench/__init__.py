"""HydroJet Bench: kinematic models, drivers and online disturbance estimation for soft
continuum robots (Campisano et al., RA-L 2020).

The analysis commands are functions here too, for notebooks and scripts (`hydrojet_bench.api`):
``load``, ``calibrate``, ``compare``, ``diagnose``, ``replay`` and ``study``, each returning a
typed result with ``to_pandas()`` and ``plot()``.
"""

__version__ = "0.1.0"

API = ("load", "calibrate", "compare", "diagnose", "replay", "study")
__all__ = ["__version__", *API]


def __getattr__(name: str):
    # Imported on first use: the command line imports this package for its version and
    # should not pay for pandas, matplotlib and the analyses it may not run.
    if name in API:
        from . import api

        return getattr(api, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
