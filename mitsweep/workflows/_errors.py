"""The error a workflow raises for its caller's input."""

__all__ = ["InputError"]


class InputError(ValueError):
    """Bad input to a workflow (a value, a file, a combination of options): the caller's
    to fix. The message is one line; where the option has a command-line spelling the
    message uses it (``--center``), so that the command prints it as it is."""
