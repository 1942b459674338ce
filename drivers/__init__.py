"""Device drivers for the HydroJet bench: one subpackage per device, each with a pure codec,
an async client over a transport chosen by URL, and a byte-level emulator.

The package stands alone: it never imports `hydrojet_bench` (its few rotation helpers are
in `drivers.rotations`), and only tests import its test doubles in `drivers.testing`.
Both rules are import-linter contracts in pyproject.toml.
"""
