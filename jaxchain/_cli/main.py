"""Entry point of the `jaxchain` command. Every subcommand's failure ends here, as one
line on stderr and an exit status; no command handles its own."""

import gc
import importlib
import os
import sys

import jax
import platformdirs

from .._errors import ValidationError
from .._engine.cache_folder import check_cache_folder
from .._engine.programs import keep_programs
from .._setup import VERSION, configure
from .common import (Parser, RunsFailed, UsageError, finish_prefetch, one_line,
                     record_outputs, usage_message)

#: The subcommands, each a module of this package with `add_parser(sub)`.
COMMANDS = ("localized", "sweep", "figure", "crosscheck", "work-precision", "boundaries",
            "stress", "basin", "snake", "mistuning", "identify", "response", "magnification",
            "localized-ranges", "server")


def build_parser(commands=COMMANDS) -> Parser:
    """The parser of the command line with the subcommands `commands` (all of them
    by default). A command's module is imported only here, so that a run loads only
    its own command's dependencies (`main` builds the parser of the one command
    named on its command line)."""
    parser = Parser(
        prog="jaxchain",
        description="Simulate rings of friction-excited oscillators (eq. (5) of "
                    "'Multiple spatially localized dynamical states in "
                    "friction-excited oscillator chains'). All quantities are "
                    "dimensionless, eqs. (4)-(6).",
        epilog="Compiled programs are kept between runs in JAX's persistent "
               "compilation cache, in the folder named by JAXCHAIN_CACHE_DIR (an "
               "empty value turns it off) or else in the user's cache folder "
               "(platformdirs.user_cache_dir('jaxchain')/xla); only you (or root) may "
               "write that folder: one that another user owns or can write is refused. "
               "After a first command, a warm process keeps JAX loaded and runs the "
               "next commands of the same environment ('jaxchain server status' shows "
               "it, 'jaxchain server stop' ends it, JAXCHAIN_SERVER=0 turns it off). "
               "JAXCHAIN_TRACEBACK=1 shows a failure's traceback.")
    parser.add_argument("--version", action="version", version=f"jaxchain {VERSION}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    for command in commands:
        module = importlib.import_module("." + command.replace("-", "_"), __package__)
        module.add_parser(sub)
    return parser


def exit_status(err: Exception) -> tuple[int, str]:
    """The exit status and the one-line message of a command's failure.

    **Arguments:**

    - `err`: the exception that ended the command's run.

    **Returns:**

    `(status, message)`: status 2 for a usage error, that is a bad option
    (`UsageError`) or an argument that the library's own checks refuse
    (`ValidationError`), with field names shown as the options a user typed; status
    1 for a failed run, that is any other exception: `RunsFailed` and `RuntimeError`
    with their message, anything else (a `ValueError` of NumPy, xarray, zarr or
    SciPy, a bracket that does not bracket, an `OSError`) with its type's name
    before it. The message is one line.
    """
    if isinstance(err, (UsageError, ValidationError)):
        return 2, usage_message(err)
    if isinstance(err, (RunsFailed, RuntimeError)):
        return 1, one_line(err)
    return 1, f"{type(err).__name__}: {one_line(err)}"


def compilation_cache() -> str | None:
    """Turn on JAX's persistent compilation cache, so that a command's second run
    skips compilation: in the folder named by the environment variable
    JAXCHAIN_CACHE_DIR, or else in the user's cache folder
    (platformdirs.user_cache_dir("jaxchain")/xla). JAXCHAIN_CACHE_DIR set to an
    empty string turns it off. Every compiled program is cached, however short
    its compilation: the small programs that prepare a run (`compiled`) cost a
    warm start their compilation otherwise. jaxchain's compiled runs hold no host
    callbacks, which JAX never caches. The traced programs are kept beside them,
    in the folder `traced` (`keep_programs`), so that a warm start neither traces
    nor compiles them.

    The process runs what the cache holds, so only this user (or root) may write
    it (`check_cache_folder`, as ssh checks `~/.ssh`); a missing folder is created
    with mode 0o700. A folder of root's that this user cannot write (a cache shared
    on a cluster, filled by its administrator) is read, never written. A folder
    that cannot be created turns the cache off.

    **Returns:**

    The folder, or None when the cache is off.

    **Raises:**

    `UsageError` naming the folder (or the folder above it, or the file in it)
    that another user owns or can write, and the fix.
    """
    folder = os.environ.get("JAXCHAIN_CACHE_DIR")
    if folder is None:
        folder = os.path.join(platformdirs.user_cache_dir("jaxchain"), "xla")
    if not folder:
        return None
    try:
        writable = check_cache_folder(folder)
        keep_programs(os.path.join(folder, "traced"))
    except ValidationError as err:
        raise UsageError(str(err)) from None
    except OSError:
        return None  # it cannot be created: no cache
    jax.config.update("jax_compilation_cache_dir", folder)
    # JAX writes an executable only if it took at least this long to compile:
    # every one, or none into a folder that is read only.
    jax.config.update("jax_persistent_cache_min_compile_time_secs",
                      0.0 if writable else float("inf"))
    return folder


def main(argv=None) -> int:
    """Run the command line, in a process set up by `jaxchain.configure()` (float64,
    one CPU device per core, the XLA flags). Figures are drawn with matplotlib's Agg
    backend unless the environment variable MPLBACKEND names another. Compiled
    programs are kept in a persistent cache (`compilation_cache`).

    **Returns:**

    The exit status (`exit_status`): 0 on success; 2 for a usage error, that is a bad
    option or an argument that the library's validation refuses (`ValidationError`)
    before anything runs; 1 when a run failed, whatever the error raised during it
    (a `ValueError` of NumPy or xarray included); 130 when interrupted. A failure is
    one line on stderr, never a traceback (set JAXCHAIN_TRACEBACK=1 to let the
    exception through).
    """
    configure()  # float64, a device per core, the XLA flags: before anything runs
    argv = sys.argv[1:] if argv is None else list(argv)
    named = [a for a in argv if a in COMMANDS][:1]
    parser = build_parser(named if named and argv[0] == named[0] else COMMANDS)
    args = parser.parse_args(argv)
    if args.command is None:
        parser.error("a COMMAND is required (see jaxchain --help)")
    set_backend = not os.environ.get("MPLBACKEND")
    if set_backend:
        # The commands write figures to files, with no window: Agg, set before
        # matplotlib is imported (only the modules that draw import it), or switched.
        os.environ["MPLBACKEND"] = "Agg"
        if "matplotlib" in sys.modules:
            sys.modules["matplotlib"].use("Agg")
    ran = False
    try:
        compilation_cache()  # a cache folder that others can write: exit status 2
        args.run(args)
        ran = True
        return 0
    except KeyboardInterrupt:
        status, message = 130, "interrupted"
    except Exception as err:
        ran = isinstance(err, RunsFailed)  # its results written, the failed runs marked
        if os.environ.get("JAXCHAIN_TRACEBACK"):
            raise
        status, message = exit_status(err)
    finally:
        record_outputs(ran)
        finish_prefetch()
        if set_backend:
            del os.environ["MPLBACKEND"]
    print(f"jaxchain {args.command}: error: {message}", file=sys.stderr)
    return status


def run_here(argv=None) -> int:
    """`main` in this process, tuned for a command's short life: Python's cyclic
    garbage collector leaves alone what the imports made (`gc.freeze`) and runs
    less often. JAX's tracing makes many objects, and full collections walking
    the imported modules took 0.4 s of a small warm run (`benchmarks/fixed_cost.py`);
    cycles are still collected. The console script (`jaxchain._cli.console.command`)
    calls it when no warm process takes the command."""
    gc.freeze()
    gc.set_threshold(50_000, 50, 100)
    return main(argv)
