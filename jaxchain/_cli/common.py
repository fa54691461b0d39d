"""What every `jaxchain` command shares: option names, the parser that fails in one
line, the errors that `main` turns into one line and an exit status, and the solver
table."""

import argparse
import contextlib
import dataclasses
import importlib
import json
import logging
import math
import os
import sys
import tempfile
import threading
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from .._engine.solver.controller import CONTROLLERS
from .._engine.engines import ENGINES, AbstractEngine, as_engine
from .._engine.exact.options import NonsmoothOptions
from .._engine.options import (ATOL_PER_EPS, DEFAULT_ATOL, DEFAULT_RTOL, RTOL_PER_EPS,
                               SimulationOptions)
from .._physics.params import ChainParams
from .._engine.solver.registry import DEFAULT_SOLVER, SOLVERS  # noqa: F401  (SOLVERS: for the commands)
from .._physics.forces import DEFAULT_EPS
from .footprint import check_footprint
from .folder_lock import command_line, lock_folder, release_folder
from .parser import Parser, UsageError  # noqa: F401  (for the commands)


#: Field names in error messages, as the options a user typed.
OPTION_NAMES = {
    "ChainParams.v_d": "--vd", "ChainParams.n_osc": "--n-osc", "Smoothed.eps": "--eps",
    "ChainParams.xi": "--xi",
    "SimulationOptions.t_end": "--t-end", "SimulationOptions.transient": "--transient",
    "SimulationOptions.rtol": "--rtol", "SimulationOptions.atol": "--atol",
    "SimulationOptions.controller": "--controller",
    "SimulationOptions.max_steps": "--max-steps", "batch_size": "--batch-size",
    "n_check": "--check",
    "NonsmoothOptions.rtol": "--ref-rtol", "NonsmoothOptions.atol": "--ref-rtol",
    "NonsmoothOptions.t_end": "--t-end", "NonsmoothOptions.transient": "--transient",
}


#: The library's simulation defaults, which the options repeat.
DEFAULTS = SimulationOptions()

def param_default(name: str) -> float:
    """The default of a `ChainParams` field as a Python float (the fields are
    NumPy arrays), for an option's default and help."""
    return float(getattr(ChainParams(), name))


class RunsFailed(Exception):
    """Some runs failed; the others' results are written and the failed ones marked.
    Raised by a command after its output: reported in one line, exit status 1."""


def positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (value > 0 and value < float("inf")):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    return value


def non_negative_float(text: str) -> float:
    """An argparse type: a finite number >= 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (0 <= value < float("inf")):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text!r}")
    return value


def tolerance(text: str) -> float:
    """An argparse type: a tolerance, a number in (0, 1)."""
    value = positive_float(text)
    if value >= 1:
        raise argparse.ArgumentTypeError(f"must be a number in (0, 1), got {text!r}")
    return value


def positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {text!r}")
    return value


def comma_list(kind):
    """An argparse type: a comma-separated list of `kind` ('' for an empty list)."""
    def parse(text: str) -> list:
        try:
            return [kind(v) for v in text.split(",") if v]
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a comma-separated list, got "
                                             f"{text!r}") from None
    return parse


def belt_speeds(text: str, at_rest: bool = False) -> list[float]:
    """An argparse type, the one grammar of --vd: a belt speed V, a comma-separated
    list V1,V2,..., or START:STOP:NUM (NUM equally spaced values from START to
    STOP, both included); each finite and > 0 (>= 0 `at_rest`, where the command
    takes a belt standing still), dimensionless."""
    try:
        if ":" in text:
            start, stop, num = text.split(":")
            num = int(num)
            if num < 1:
                raise argparse.ArgumentTypeError(f"NUM must be >= 1, got {text!r}")
            values = np.linspace(float(start), float(stop), num).round(12).tolist()
        else:
            values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected V, a list V1,V2,... or START:STOP:NUM, got {text!r}") from None
    if not values:
        raise argparse.ArgumentTypeError(f"expected at least one belt speed, got {text!r}")
    if not all(np.isfinite(v) and (v >= 0 if at_rest else v > 0) for v in values):
        bound = ">= 0 (0: the belt at rest)" if at_rest else "> 0"
        raise argparse.ArgumentTypeError(f"belt speeds must be finite and {bound}, got "
                                         f"{text!r}")
    return values


def one_belt_speed(text: str, at_rest: bool = False) -> float:
    """An argparse type: --vd of a command that starts from one belt speed, in the
    grammar of `belt_speeds`, refused (in one line) when it names several."""
    values = belt_speeds(text, at_rest)
    if len(values) != 1:
        raise argparse.ArgumentTypeError(f"this command starts from one belt speed, got "
                                         f"{len(values)} ({text!r})")
    return values[0]


def belt_speed_or_rest(text: str) -> float:
    """An argparse type: `one_belt_speed` where the belt may stand still (0: a
    forced chain's friction damper)."""
    return one_belt_speed(text, at_rest=True)


#: The metavar of --vd in every command.
VD_FORMS = "V|V,V,...|START:STOP:NUM"


class DefaultSpeeds(list):
    """The default belt speeds of --vd, told apart from speeds the user gave (a
    chain file's own v_d then replaces them, `speeds_of_chain`)."""


def speeds_of_chain(args, params) -> list[float]:
    """The belt speeds to run: --vd as given, or the chain's v_d (a chain file's, in
    SI units its belt_speed) when --vd was not given and --chain was."""
    if isinstance(args.vd, DefaultSpeeds) and getattr(args, "chain", None) is not None:
        return [float(params.v_d)]
    return list(args.vd)


def add_vd_option(g, default, help: str) -> None:
    """--vd in the grammar of `belt_speeds`, `default` a list of belt speeds (or None
    where the command chooses), in the argument group (or parser) `g`."""
    shown = "the command's choice" if default is None else ",".join(f"{v:g}" for v in default)
    default = None if default is None else DefaultSpeeds(default)
    g.add_argument("--vd", type=belt_speeds, default=default, metavar=VD_FORMS,
                   help=f"{help} (default {shown})")


def add_model_options(p: argparse.ArgumentParser, *, vd: float, n_osc: int) -> None:
    """--vd, --n-osc, --eps: the chain (other parameters are eq. (7) of the paper)."""
    g = p.add_argument_group("model (eq. (5) of the paper; other parameters eq. (7))")
    add_vd_option(g, [vd], "belt speeds v_d, dimensionless, each run in turn")
    add_ring_options(g, n_osc=n_osc)


def add_ring_options(g, *, n_osc: int = 20) -> None:
    """--n-osc and --eps, in the argument group (or parser) `g`."""
    g.add_argument("--n-osc", type=positive_int, default=n_osc, metavar="N",
                   help=f"number of oscillators on the ring (default {n_osc})")
    eps = DEFAULT_EPS
    g.add_argument("--eps", type=positive_float, default=eps,
                   help=f"tanh smoothing velocity of sign(v_rel) (default {eps:g})")


def add_run_options(p: argparse.ArgumentParser, defaults: SimulationOptions = DEFAULTS
                    ) -> None:
    """--t-end and --transient (defaults those of `defaults`), then the solver
    options (`add_solver_options`)."""
    g = p.add_argument_group("integration")
    g.add_argument("--t-end", type=positive_float, default=defaults.t_end, metavar="T",
                   help=f"final time, in units of 1/omega_n (default {defaults.t_end:g})")
    g.add_argument("--transient", type=float, default=defaults.transient, metavar="T",
                   help=f"observables are taken after this time (default "
                        f"{defaults.transient:g})")
    add_solver_options(g)


def add_solver_options(g, rtol: float = DEFAULTS.rtol, atol: float = DEFAULTS.atol) -> None:
    """--solver, --rtol, --atol, --controller and --max-steps, with the library's
    defaults, in the argument group (or parser) `g`: the same in every command
    that integrates (`rtol`, `atol`: where the command's library function has
    other defaults)."""
    g.add_argument("--engine", choices=list(ENGINES), default="smoothed",
                   help="the model of friction: smoothed (default: sign(v_rel) smoothed "
                        "as tanh(v_rel/eps), integrated by --solver) or exact (the "
                        "stick/slip switch model, Leine et al. 1998: stick exact, no eps, "
                        "switches located as events; slower)")
    g.add_argument("--solver", choices=sorted(SOLVERS) + ["auto"], default=DEFAULT_SOLVER,
                   help=f"the smoothed engine's diffrax solver (default {DEFAULT_SOLVER}, "
                        "a Rosenbrock-W method "
                        "whose W is the diagonal friction Jacobian); kencarp* are IMEX, "
                        "with the friction force implicit; auto takes tsit5 where "
                        "mu_st/eps <= 100 and ros34pw2 elsewhere")
    add_tolerance_options(g, rtol, atol)
    g.add_argument("--max-steps", type=positive_int, default=DEFAULTS.max_steps,
                   help=f"step budget per chunk of {DEFAULTS.chunk_length:g} time units "
                        f"(default {DEFAULTS.max_steps})")


#: The options of `add_run_options` and `add_tolerance_options` that set a field of
#: `SimulationOptions` of the same name.
_RUN_FIELDS = ("t_end", "transient", "rtol", "atol", "max_steps", "controller")


def simulation_options(args, **fields) -> SimulationOptions:
    """The `SimulationOptions` of a command: its run options (those its parser has
    of --t-end, --transient, --rtol, --atol, --max-steps, --controller), then
    `fields`, which override them; the library's defaults for the rest.

    **Raises:**

    `ValidationError` for a bad combination (transient >= t_end, say), and
    `UsageError` for a run that this machine cannot hold (`check_footprint`): exit
    status 2.
    """
    given = {name: getattr(args, name) for name in _RUN_FIELDS if hasattr(args, name)}
    options = SimulationOptions(**(given | fields))
    check_footprint(*_size_of_chain(args), options)
    return options


def _size_of_chain(args) -> tuple[int, str]:
    """The number of oscillators that a command's options name (--lattice, --n-osc)
    before its chain is built, and the option in words (1 where they name none: a
    chain file's chain is estimated when it is read, `chain_params`)."""
    lattice = getattr(args, "lattice", None)
    if lattice is not None:
        n_osc = lattice[0] * lattice[1]
        return n_osc, f"--lattice {lattice[0]}x{lattice[1]} ({n_osc} oscillators)"
    n_osc = getattr(args, "n_osc", None)
    n_osc = n_osc if isinstance(n_osc, int) else 1
    return n_osc, f"--n-osc {n_osc}"


def engine_of(args, options: SimulationOptions, params: ChainParams | None = None
              ) -> AbstractEngine:
    """The engine that --engine names, with the command's solver and eps (--solver,
    --eps, the smoothed engine's; "auto" resolved with `params`) and `options` (the
    exact engine takes their horizon, and its own tolerances unless --rtol or
    --atol was typed)."""
    return _ENGINE_OF[getattr(args, "engine", "smoothed")](args, options, params)


def _smoothed_of(args, options: SimulationOptions, params: ChainParams | None):
    return as_engine("smoothed", args.solver, options, params, eps=args.eps)


def _exact_of(args, options: SimulationOptions, params: ChainParams | None):
    engine = as_engine("exact", options=options)
    # --rtol, --atol typed on the command line set the exact engine's tolerances
    # too; their defaults are the smoothed engine's
    given = {name: getattr(args, name) for name in getattr(args, "typed_tolerances", ())}
    return dataclasses.replace(engine, options=dataclasses.replace(engine.options, **given))


#: The engine of each --engine name, from the command's options.
_ENGINE_OF = {"smoothed": _smoothed_of, "exact": _exact_of}


def engine_record(engine: AbstractEngine) -> dict:
    """The engine of a command for its JSON: its name and every setting that shapes
    its results (`AbstractEngine.attributes`)."""
    return engine.attributes()


def engine_text(engine: AbstractEngine) -> str:
    """The engine of a command for its table's heading: its model and solver."""
    solver = engine.attributes()["solver"]
    return f"{engine.describe()}, {solver}"


def smoothed_only(args, what: str) -> None:
    """Refuse --engine exact in one line (exit status 2) where the command cannot
    run it: `what` says why.

    **Raises:**

    `UsageError` when --engine is exact."""
    if not ENGINES[getattr(args, "engine", "smoothed")].smooths:
        raise UsageError(f"--engine {args.engine}: {what}; run it with --engine smoothed")


class _Typed(argparse.Action):
    """Store the value, and the option's name in `typed_tolerances`: an option
    typed on the command line, not left at its default."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, values)
        namespace.typed_tolerances = (*getattr(namespace, "typed_tolerances", ()), self.dest)


def add_tolerance_options(g, rtol: float = DEFAULTS.rtol, atol: float = DEFAULTS.atol
                          ) -> None:
    """--rtol, --atol (defaults `rtol`, `atol`; None: the smoothed engine's follow
    --eps, `follow_eps`), each in (0, 1), and --controller, in the argument group (or
    parser) `g`."""
    exact = NonsmoothOptions()
    shown = {"rtol": f"min({DEFAULT_RTOL:g}, eps/{RTOL_PER_EPS:g})" if rtol is None
             else f"{rtol:g}",
             "atol": f"min({DEFAULT_ATOL:g}, eps/{ATOL_PER_EPS:g})" if atol is None
             else f"{atol:g}"}
    g.add_argument("--rtol", type=tolerance, default=rtol, action=_Typed,
                   help=f"relative tolerance, in (0, 1) (default {shown['rtol']}; with "
                        f"--engine exact {exact.rtol:g})")
    g.add_argument("--atol", type=tolerance, default=atol, action=_Typed,
                   help=f"absolute tolerance, in (0, 1) (default {shown['atol']}; with "
                        f"--engine exact {exact.atol:g})")
    g.add_argument("--controller", choices=list(CONTROLLERS), default=DEFAULTS.controller,
                   help=f"step-size controller (default {DEFAULTS.controller}: a PI "
                        "controller that may shrink after an accepted step and, after "
                        "two rejections, uses the order the error showed; diffrax: "
                        "diffrax's integral controller, the one jaxchain used first)")


#: The figure formats of --format.
FIGURE_FORMATS = ("png", "pdf", "svg")


def _figure_formats(text: str) -> list[str]:
    """An argparse type: a comma-separated list of `FIGURE_FORMATS`."""
    names = [v.strip().lower() for v in text.split(",") if v.strip()]
    unknown = [v for v in names if v not in FIGURE_FORMATS]
    if not names or unknown:
        raise argparse.ArgumentTypeError(f"expected formats of {','.join(FIGURE_FORMATS)}, "
                                         f"got {text!r}")
    return list(dict.fromkeys(names))


def add_output_options(p: argparse.ArgumentParser, *, resume: str | None = None,
                       figures: bool = True) -> None:
    """--out, --overwrite, --wait, --resume (where the command resumes: `resume` says
    what it continues), --format (where it draws), --json and --no-progress."""
    g = p.add_argument_group("output")
    g.add_argument("--out", type=Path, default=Path("jaxchain-out"), metavar="DIR",
                   help="folder of the results (default ./jaxchain-out/)")
    g.add_argument("--overwrite", action="store_true",
                   help="replace this command's results in DIR (refused by default)")
    g.add_argument("--wait", action="store_true",
                   help="wait for a command that is writing into DIR to end (by default "
                        "this one is refused: one command at a time per folder)")
    if resume is not None:
        g.add_argument("--resume", action="store_true", help=f"continue {resume}")
    if figures:
        g.add_argument("--format", type=_figure_formats, default=["png"], metavar="FMT,...",
                       help=f"figure formats, of {','.join(FIGURE_FORMATS)} (default png)")
    g.add_argument("--json", action="store_true",
                   help="print one JSON document on stdout, with the paths of the "
                        "files written under 'outputs', instead of the table")
    g.add_argument("--no-progress", action="store_true", help="hide the progress bar")


class Outputs:
    """The files a command writes under --out: claimed before it computes, written
    whole or not at all, and listed by name in its JSON (`as_json`).

    The folder is locked from here to the end of the command (`lock_folder`,
    released by `record_outputs`): a second command into it is refused in one line
    naming the first, or waits for it with --wait.

    Each file written is recorded in the folder's `MANIFEST` with the command and
    the digest of its settings (`_settings_digest`). A claimed file that exists is
    replaced when the manifest says that this command made it with the same
    settings (a command run twice; `again` is then True, and a note says so);
    otherwise it is refused (`UsageError`, exit status 2) unless --overwrite, or
    --resume where the command resumes: no result is lost silently.
    """

    def __init__(self, args, data: Sequence[str] = (), figures: Sequence[str] = ()):
        self.folder = Path(args.out)
        self.formats = getattr(args, "format", ["png"])
        self.written: dict[str, Path] = {}
        self.made_by = {"command": getattr(args, "command", None),
                        "settings": _settings_digest(args)}
        self.locked = False
        _OUTPUTS.append(self)
        claimed = list(data) + [f"{stem}.{fmt}" for stem in figures for fmt in self.formats]
        _writable_folder(self.folder)
        lock_folder(self.folder, command_line(self.made_by["command"], self.folder),
                    wait=getattr(args, "wait", False))
        self.locked = True
        existing = [name for name in claimed if (self.folder / name).exists()]
        made = self._manifest()
        self.again = bool(existing) and all(made.get(n) == self.made_by for n in existing)
        if getattr(args, "overwrite", False) or getattr(args, "resume", False):
            return
        if self.again:
            note(f"jaxchain {self.made_by['command']}: --out {self.folder} holds this "
                 f"command's results with the same settings: they are written again (a store's "
                 f"finished batches kept)")
        elif existing:
            other = [n for n in existing if n not in made]
            why = ("" if other else
                   " (made by another command or with other settings)")
            name = (other or existing)[0]
            again = " (or --resume to continue it)" if hasattr(args, "resume") else ""
            raise UsageError(f"--out {self.folder}: {name} exists{why}; give "
                             f"--overwrite to replace it{again}")

    def _manifest(self) -> dict:
        try:
            return json.loads((self.folder / MANIFEST).read_text())
        except (OSError, ValueError):
            return {}

    def path(self, name: str) -> Path:
        """Where `name` goes, recorded as written (a store the library writes); in
        the folder's manifest once the command has run (`record_outputs`)."""
        self.written[name] = self.folder / name
        return self.written[name]

    def record(self) -> None:
        """Name this command and its settings in the folder's manifest for each
        file it wrote, written beside it and renamed into place."""
        made = self._manifest() | {name: self.made_by for name, path in self.written.items()
                                   if path.exists()}
        partial = self.folder / f"{MANIFEST}.{os.getpid()}.partial"
        partial.write_text(json.dumps(made, indent=1, sort_keys=True))
        os.replace(partial, self.folder / MANIFEST)

    def dataset(self, ds, name: str) -> Path:
        """Write `ds` to netCDF (`save_dataset`)."""
        from .._sweeps.datasets import save_dataset

        return save_dataset(ds, self.path(name))

    def text(self, text: str, name: str) -> Path:
        """Write `text` (`write_text`)."""
        from .._sweeps.atomic import write_text

        return write_text(self.path(name), text)

    def figure(self, fig, stem: str) -> list[Path]:
        """Write the matplotlib figure `fig` as `stem` in every --format, then
        close it."""
        from .._sweeps.atomic import save_figure

        return [save_figure(fig, self.path(f"{stem}.{fmt}"), close=(i == len(self.formats) - 1))
                for i, fmt in enumerate(self.formats)]

    def as_json(self) -> dict[str, str]:
        """Each written file's name (relative to --out) and path."""
        return {name: str(path) for name, path in self.written.items()}

    def summary(self) -> str:
        """The written files, for the note on standard error."""
        return "wrote " + ", ".join(str(p) for p in self.written.values())


#: The file in an output folder that names, for each result in it, the command and
#: the digest of the settings that made it (`Outputs`).
MANIFEST = ".jaxchain-results.json"

#: Options that change how a command shows its results, not what they are.
_PRESENTATION = ("run", "command", "out", "overwrite", "wait", "resume", "json",
                 "no_progress", "format")


def _settings_digest(args) -> str:
    """The digest of a command's settings: every option but those of `_PRESENTATION`,
    with the content of each file an option names (a chain file, a friction table,
    records; in lists too): an edited input is other settings. An input that is not
    a regular file (standard input, a folder) makes the digest unique: a command
    that reads one never counts as run again with the same settings."""
    import hashlib

    def identity(value):
        if isinstance(value, (list, tuple)):
            return [identity(v) for v in value]
        if isinstance(value, str) and value.startswith("table:"):
            return ["table:", identity(Path(value[6:]))]
        if isinstance(value, (str, Path)) and str(value) and len(str(value)) < 4096:
            path = Path(value)
            with contextlib.suppress(OSError):
                if path.is_file() and not str(path).startswith("/dev/"):
                    return [str(value), hashlib.sha256(path.read_bytes()).hexdigest()]
                if isinstance(value, Path) and path.exists():
                    return [str(value), os.urandom(8).hex()]
        return value

    chosen = {name: identity(value) for name, value in sorted(vars(args).items())
              if name not in _PRESENTATION}
    text = json.dumps(chosen, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


#: The outputs of the command that runs, recorded in their folders' manifests
#: when it ends (`record_outputs`).
_OUTPUTS: list[Outputs] = []


def record_outputs(ran: bool) -> None:
    """At the end of a command: when it ran (its results written, some runs failed
    perhaps), record its files in their folders' manifests; when it was refused or
    failed before its results, record nothing, so that a folder it refused is left
    as it was. Either way, release the folders' locks (`release_folder`)."""
    while _OUTPUTS:
        outputs = _OUTPUTS.pop()
        try:
            if ran:
                with contextlib.suppress(OSError):
                    outputs.record()
        finally:
            if outputs.locked:
                release_folder(outputs.folder)


def print_json(payload: dict, outputs: Outputs) -> None:
    """Print the command's one JSON document on stdout: `payload` with the written
    files under "outputs" (non-finite numbers as null)."""
    print(json.dumps(_json_ready(payload | {"outputs": outputs.as_json()}), allow_nan=False))


def report(summary: dict, outputs: Outputs, name: str, as_json: bool,
           table: Callable[[dict], None], wall: float) -> None:
    """The end of a study's command: its `summary` written to the JSON file `name`
    beside its other outputs, then shown: the one JSON document on stdout with
    `--json` (`print_json`), otherwise `table`'s lines and a note of the wall time
    and the files written."""
    outputs.text(json.dumps(_json_ready(summary), allow_nan=False), name)
    if as_json:
        print_json(summary, outputs)
    else:
        table(summary)
        note(f"{wall:.0f} s; {outputs.summary()}")


def note(text: str) -> None:
    """A note for the user (wall time, files written, a warning): standard error,
    so that standard output carries only the table or the JSON."""
    print(text, file=sys.stderr)


def scheduler(text: str) -> str:
    """An argparse type: a Dask scheduler's address, or local:N."""
    from .._engine.cluster import local_workers  # imports Dask only when asked

    try:
        local_workers(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err).split(": ", 1)[1]) from None
    return text


def add_scheduler_option(g) -> None:
    """--scheduler, in the argument group (or parser) `g`."""
    g.add_argument("--scheduler", type=scheduler, default=None, metavar="ADDRESS|local:N",
                   help="run the batches as tasks on a Dask cluster: the address of its "
                        "scheduler (tcp://HOST:8786, its workers started by `dask worker`, "
                        "dask-jobqueue or dask-cuda, with the store on a file system "
                        "they share), or local:N to start N worker processes of one core "
                        "each on this machine (default: run in this process)")


@contextlib.contextmanager
def cluster_client(args):
    """The `distributed.Client` of --scheduler (a `LocalCluster` for local:N, closed
    at the end), or None when the option is not given. Dask's own log (its
    tracebacks when a connection drops) is silenced: the command reports a failure
    in one line."""
    if getattr(args, "scheduler", None) is None:
        yield None
        return
    from .._engine.cluster import connect

    for name in ["distributed", "tornado", "asyncio", *logging.root.manager.loggerDict]:
        if name.split(".")[0] in ("distributed", "tornado", "asyncio"):
            logging.getLogger(name).setLevel(logging.CRITICAL)  # Dask sets some one by one
    with connect(args.scheduler) as client:
        yield client


def one_line(err: BaseException) -> str:
    """The message of `err` in one line: the first non-empty line, and for an error
    raised inside compiled code (`eqx.error_if`) the message itself rather than the
    stack that equinox puts before it."""
    text = str(err)
    marker = "EquinoxRuntimeError: "
    if marker in text:
        text = text.split(marker, 1)[1]
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    return lines[0] if lines else type(err).__name__


def usage_message(err: Exception) -> str:
    """A `UsageError`, or a `ValidationError` of the library, in one line, with field
    names replaced by option names."""
    text = one_line(err)
    for field, option in OPTION_NAMES.items():
        text = text.replace(field, option)
    return text


def _writable_folder(path: Path) -> None:
    """Create the output folder now, before any computation.

    **Raises:**

    `UsageError` naming --out if its name is not UTF-8 (netCDF, JSON and the
    manifest name their files in UTF-8), or if it cannot be created or written."""
    try:
        str(path).encode("utf-8")
    except UnicodeEncodeError:
        shown = os.fsencode(path).decode("utf-8", "backslashreplace")
        raise UsageError(f"--out {shown}: the folder's name is not UTF-8; choose a name "
                         f"in UTF-8") from None
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError as err:
        raise UsageError(f"--out {path}: cannot write there ({err.strerror})") from None


def prefetch(*modules: str) -> None:
    """Import `modules` in a background thread, so that their import (xarray and
    matplotlib take a second or two) overlaps the run: XLA releases the GIL while it
    compiles and integrates. The module that needs one imports it as usual, after the
    run, and waits for the thread if it is still importing it."""
    def load():
        for name in modules:
            importlib.import_module(name)

    thread = threading.Thread(target=load, name="jaxchain-prefetch", daemon=True)
    _PREFETCHING.append(thread)
    thread.start()


#: What writing a command's results imports: xarray, which imports dask.array at its
#: first variable when Dask is installed (0.3-0.9 s), the netCDF engine and
#: matplotlib. A command prefetches them (`prefetch`) while its run goes on.
RESULT_MODULES = ("xarray", "dask.array", "h5netcdf", "matplotlib.pyplot")

#: The prefetch threads started by this process's command, joined when it returns.
_PREFETCHING: list[threading.Thread] = []


def finish_prefetch() -> None:
    """Wait for the command's prefetch threads: a command that returns early (a bad
    option found after they started) leaves no import half done behind it, for a
    caller of `jaxchain.main` that goes on to use matplotlib."""
    while _PREFETCHING:
        _PREFETCHING.pop().join()


def _json_ready(obj):
    """Replace non-finite floats (failed runs) by None, so that the output is JSON."""
    if isinstance(obj, dict):
        return {k: _json_ready(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_ready(v) for v in obj]
    if isinstance(obj, (np.ndarray, np.generic)):
        return _json_ready(obj.tolist())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def show_progress(args) -> bool:
    return not args.no_progress and sys.stderr.isatty()
