"""The `jaxchain` console script: a command runs in the warm process of its
environment (`jaxchain._cli.warm`), or here, after which the warm process is
started for the next commands. Standard library only until the command runs
here."""

import atexit
import os
import sys

from .warm import enabled, forward, start


def command() -> None:
    """The `jaxchain` console script: `jaxchain server ...` here and at once
    (`jaxchain._cli.server`); any other command in the warm process (`forward`),
    or here (`jaxchain._cli.main.run_here`), after which the warm process is
    started (`start`). The process then ends without the interpreter's teardown
    (`os._exit`, after the exit functions and a flush of standard output and
    error): freeing every module and the JAX runtime's objects one by one took
    0.7 s and serves nothing, as every file is written and closed by then
    (`benchmarks/fixed_cost.py`)."""
    argv, env = sys.argv[1:], dict(os.environ)  # the environment before the command's set-up
    if argv[:1] == ["server"]:
        from .server import run_alone

        status = run_alone(argv)
    else:
        try:
            status = forward(argv, env)
        except KeyboardInterrupt:  # while waiting for a warm process to start
            print("jaxchain: error: interrupted", file=sys.stderr)
            status = 130
        if status is None:
            from .main import run_here

            status = run_here(argv)
            if enabled(env) and status in (0, 1) and argv and not argv[0].startswith("-"):
                start(env)
    try:
        atexit._run_exitfuncs()
        sys.stdout.flush()
        sys.stderr.flush()
    except BrokenPipeError:  # the reader of our output went away: nothing to say
        pass
    os._exit(status)


if __name__ == "__main__":
    command()
