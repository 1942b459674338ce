"""Which steps of a session train the models and which ones score them.

The split: the calibration poses (sweep -1) and the FIRST run of every kind of
validation sweep train; every later repetition of a sweep is held out. A sweep's kind is
its sequence of commanded jet forces, so the paper's protocol (40 poses, then jets 1, 2,
3 swept three times) trains on the poses plus one sweep of each jet (103 steps) and holds
out the other two repetitions (126 steps). Why this split:

* every signature a held-out step can show (each jet, loading and unloading, every bend)
  was seen in training, so an effect is judged on whether it explains the physics, not
  on whether it extrapolates to a jet it never saw (leave-one-jet-out would condemn
  jet_gain for a jet whose gain no training step shows);
* the held-out steps repeat training commands with fresh noise: an extra parameter that
  fits noise in training gains nothing there, which is what cross-validation is for;
* one fit per candidate instead of one per fold keeps the library's candidates within seconds.

Sweeps that never repeat are all held out (the model then trains on the calibration
poses alone, the paper's own split). In the paper's protocol the training steps come
first, so training follows the recorded path exactly; in other layouts held-out steps
between training steps are still solved, in recorded order, to carry the path state of
a hysteretic clamp (see `calibrate`'s ``fitted``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...data.dataset import Dataset
from ...errors import UserError

# Commanded forces of two sweeps match when they agree to this (N): commands repeat
# exactly, and a CSV prints them to at least 6 digits.
FORCE_MATCH_N = 1e-6
MIN_TRAINING_STEPS = 10


@dataclass(frozen=True)
class Split:
    """Boolean masks over the session's steps (in recorded order).

    training: valid steps the models are fitted to. held_out: valid steps they are
    scored on. solved: the prefix of the session a fit must solve along its path (up to
    the last training step). held_out_sweeps: the sweep ids scored.
    """

    training: np.ndarray
    held_out: np.ndarray
    solved: np.ndarray
    held_out_sweeps: tuple[int, ...]

    @property
    def description(self) -> str:
        return (f"trained on {int(self.training.sum())} steps (calibration poses and the first run of each "
                f"kind of sweep), scored on {int(self.held_out.sum())} held-out steps of sweeps "
                f"{', '.join(map(str, self.held_out_sweeps))}")

    def as_dict(self) -> dict:
        return {"training_steps": int(self.training.sum()), "held_out_steps": int(self.held_out.sum()),
                "held_out_sweeps": list(self.held_out_sweeps),
                "rule": "calibration poses and the first run of each kind of sweep train; "
                        "later repetitions are held out"}


def sweep_kinds(steps: Dataset) -> dict[int, int]:
    """Sweep id -> kind index: sweeps with the same commanded force sequence share a kind
    (kinds numbered in order of first appearance)."""
    kinds: dict[int, int] = {}
    signatures: list[np.ndarray] = []
    for sweep in steps.sweep_ids():
        forces = steps.jet_forces_n[steps.sweep == sweep]
        for kind, signature in enumerate(signatures):
            if signature.shape == forces.shape and np.all(np.abs(signature - forces) <= FORCE_MATCH_N):
                kinds[sweep] = kind
                break
        else:
            kinds[sweep] = len(signatures)
            signatures.append(forces)
    return kinds


def split_session(steps: Dataset) -> Split:
    """The training/held-out split of a session's quasistatic steps (see the module
    docstring). Raises UserError when nothing can be held out or too little trains."""
    kinds = sweep_kinds(steps)
    counts: dict[int, int] = {}
    for kind in kinds.values():
        counts[kind] = counts.get(kind, 0) + 1
    first_of_kind = {}
    for sweep in sorted(kinds):
        first_of_kind.setdefault(kinds[sweep], sweep)
    valid = steps.valid_mask()
    training = steps.sweep == -1
    held_out = np.zeros(len(steps), dtype=bool)
    for sweep, kind in kinds.items():
        rows = steps.sweep == sweep
        if counts[kind] > 1 and first_of_kind[kind] == sweep:
            training |= rows
        else:
            held_out |= rows
    training &= valid
    held_out &= valid
    name = steps.source or "the data"
    if not held_out.any():
        raise UserError(f"{name}: no validation sweeps (sweep >= 0) to hold out; diagnose needs sweeps "
                        "besides the calibration poses (e.g. the paper protocol of `simulate`)")
    if training.sum() < MIN_TRAINING_STEPS:
        raise UserError(f"{name}: only {int(training.sum())} valid training steps (calibration poses and "
                        f"first sweeps); diagnose needs at least {MIN_TRAINING_STEPS}")
    solved = np.zeros(len(steps), dtype=bool)
    solved[:int(np.flatnonzero(training)[-1]) + 1] = True
    return Split(training, held_out, solved, tuple(int(s) for s in np.unique(steps.sweep[held_out])))
