"""The launcher's one error type: a run that cannot start or go on, said in one line.

Room: deploy, the wiring. May import: nothing.
"""


class LaunchError(RuntimeError):
    """A run could not start or go on; the message is the one line the user sees."""
