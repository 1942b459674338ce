"""Error types shared across the bench.

`UserError` marks a mistake the user can fix (a bad file, key, value or option). The
command line prints its message without a traceback; anything else is a bug and keeps
its traceback.
"""


class UserError(Exception):
    """A problem in the user's input; the message names the file, row, key or field."""


class ConvergenceError(RuntimeError):
    """A model solve did not reach equilibrium; no answer is returned rather than a wrong one."""
