"""Kinematic models of the HydroJet: Cosserat rod and pseudo-rigid-body chain."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, runtime_checkable

from ..errors import UserError
from ..params import ModelParameters
from ..effects.problem import RodProblem
from .shooting import CosseratModel, PrbModel, PreparedProblem, ShootingModel, Solution

__all__ = ["CosseratModel", "KinematicModel", "PrbModel", "PreparedProblem", "RodProblem",
           "ShootingModel", "Solution", "make_model"]


@runtime_checkable
class KinematicModel(Protocol):
    """g = f(q, zeta) (paper eq. 1): jet forces and parameters to an equilibrium shape."""

    name: str

    def solve(self, jet_forces_n: Sequence[float], params: ModelParameters, *,
              previous: Solution | None = None, warm_start: Solution | None = None) -> Solution: ...


MODELS = {"cosserat": CosseratModel, "prb": PrbModel}


def make_model(name: str, effects: Sequence = ("gravity",)) -> ShootingModel:
    """A model by name (``cosserat`` or ``prb``) with the given effects."""
    try:
        return MODELS[name](effects)
    except KeyError:
        raise UserError(f"unknown model {name!r}; choose one of: {', '.join(MODELS)}") from None
