"""Error types shared across the bench.

`UserError` marks a mistake the user can fix (a bad file, key, value or option). The
command line prints its message without a traceback; anything else is a bug and keeps
its traceback.
"""


class UserError(Exception):
    """A problem in the user's input; the message names the file, row, key or field."""


class ConvergenceError(RuntimeError):
    """A model solve did not reach equilibrium; no answer is returned rather than a wrong one."""


class EffectOutputError(UserError, ValueError):
    """Effects left the rod problem unsolvable (a wrong shape, a non-finite value, a
    non-positive stiffness): the user's effect file or its parameter values. A ValueError
    too, so a fit that meets it at a trial value treats it as any failed solve."""
