"""The library's own exception for a bad argument."""


class ValidationError(ValueError):
    """A bad argument or option of a public entry point, found by the library's own
    checks before anything runs: its message names the argument, its value and what
    is accepted. A subclass of `ValueError`, so that `except ValueError` still
    catches it; the command line reports it as a usage error (exit status 2), while
    any other error raised during a run (NumPy's, xarray's, a bracket that does not
    bracket) is a failed run (exit status 1)."""
