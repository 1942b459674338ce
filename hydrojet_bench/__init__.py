"""HydroJet Bench: kinematic models, drivers and online disturbance estimation for soft
continuum robots (Campisano et al., RA-L 2020)."""

__version__ = "0.1.0"
