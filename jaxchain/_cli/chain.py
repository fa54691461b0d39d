"""The chain options every command takes: --boundary, --friction, --mistuning,
--mistuning-seed and --chain (and --force where the command takes a forced chain),
and the `ChainParams` they give."""

import argparse
from pathlib import Path

from .._physics.chain import BOUNDARIES, Graph
from .._physics.forcing import Forcing
from .._physics.friction import FRICTION_LAWS, Tabulated
from .._physics.mistuning import mistune
from .._physics.params import ChainParams
from .._errors import ValidationError
from .._physics.record import chain_from_file
from .._engine.options import SimulationOptions
from .common import UsageError, check_footprint, non_negative_float

CHAIN_HELP = """\
The chain: --boundary ring (eq. (5) of the paper, the default), free (an open line)
or fixed (an open line tied to the ground at both ends); --lattice ROWSxCOLS makes
it a 2-D lattice (oscillator r*cols + c at row r, column c, 0-based) whose two
directions take --boundary (ring: periodic); --friction NAME:key=value,...
with NAME one of exponential (eq. (1): mu_st, mu_d, v0; the default), stribeck
(mu_s, mu_c, v_s, delta, viscous), polynomial (c0, c1, c2, c3) or coulomb (mu), for
example --friction stribeck:mu_s=1,mu_c=0.5,v_s=0.5,delta=2,viscous=0.05 (missing
keys take the law's defaults), or --friction table:FILE.csv, a measured curve (columns
v and mu, v >= 0 increasing; monotone cubic interpolation, held constant beyond the
table); --mistuning SIGMA --mistuning-seed S draws the stiffnesses
1 + delta_n, delta_n normal with standard deviation SIGMA; --chain FILE reads a TOML
file of chain settings, which override the options above (the schema is in the
documentation, "Chain files"): n_osc, boundary, lattice = [ROWS, COLS] or links =
[[i, j], ...], xi, eta_c (one value per link), stiffness, load, mass (one value per
oscillator), friction = "NAME" with the law's parameters or friction = "table" with
table = "FILE.csv", mistuning_sigma, mistuning_seed, force_amplitude,
force_frequency with force_phase (one value or one per oscillator) or
force_engine_order (where the command takes a forced chain), and units = "SI" for a
chain in kg, N/m, N s/m, N and m/s."""


def add_chain_options(g, mistuning: bool = True, forcing: bool = False) -> None:
    """--boundary, --friction, --mistuning, --mistuning-seed and --chain, in the
    argument group (or parser) `g`; without --mistuning and --mistuning-seed where
    the command draws the mistuning itself (mistuning); with --force where the
    command takes a forced chain (`forcing`; the other commands refuse a chain file
    with a force)."""
    g.add_argument("--boundary", choices=BOUNDARIES, default="ring",
                   help="ring (eq. (5), default), free or fixed ends (of each direction "
                        "of a lattice)")
    g.add_argument("--lattice", type=_lattice_size, default=None, metavar="ROWSxCOLS",
                   help="a 2-D lattice of ROWS x COLS oscillators (sets the number of "
                        "oscillators)")
    g.add_argument("--friction", default=None, metavar="NAME:k=v,...",
                   help=f"friction law, one of {', '.join(FRICTION_LAWS)} with its "
                        "parameters (default eq. (1) of the paper, exponential)")
    if mistuning:
        g.add_argument("--mistuning", type=non_negative_float, default=None, metavar="SIGMA",
                       help="standard deviation of random stiffness mistuning delta_n "
                            "(default none)")
        g.add_argument("--mistuning-seed", type=int, default=0, metavar="S",
                       help="seed of the JAX PRNG key of the mistuning draw (default 0)")
    if forcing:
        g.add_argument("--force", type=_force, default=None, metavar="A,OMEGA[,R]",
                       help="a harmonic force A cos(OMEGA t + 2 pi R n / N) on each "
                            "oscillator n: amplitude A (in units of the normal load), "
                            "frequency OMEGA (in units of omega_n) and engine order R "
                            "(default 0: in phase), the bladed disk's travelling wave")
    g.add_argument("--chain", type=Path, default=None, metavar="FILE",
                   help="TOML file of chain settings (per-oscillator arrays included); "
                        "see the chain paragraph of --help")


def _lattice_size(text: str) -> tuple[int, int]:
    rows, sep, cols = text.lower().partition("x")
    try:
        size = (int(rows), int(cols))
    except ValueError:
        size = None
    if not sep or size is None or min(size) < 1:
        raise argparse.ArgumentTypeError(f"expected ROWSxCOLS, two integers >= 1 such as "
                                         f"4x5, got {text!r}")
    return size


def _force(text: str) -> tuple[float, float, int]:
    """(amplitude, frequency, engine order) of --force A,OMEGA[,R]."""
    parts = text.split(",")
    try:
        if len(parts) not in (2, 3):
            raise ValueError
        amplitude, frequency = float(parts[0]), float(parts[1])
        order = int(parts[2]) if len(parts) == 3 else 0
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected A,OMEGA or A,OMEGA,R (amplitude, "
                                         f"frequency, integer engine order), got "
                                         f"{text!r}") from None
    return amplitude, frequency, order


def _parse_friction(text: str | None):
    """The friction law of `--friction NAME:key=value,...` (None: eq. (1)).

    **Raises:**

    `UsageError` naming --friction for an unknown law or key, a value that is not a
    number, or parameters the law refuses.
    """
    if text is None:
        return None
    name, _, rest = text.partition(":")
    if name == "table":
        try:
            return Tabulated.from_csv(rest)
        except ValidationError as err:
            raise UsageError(f"--friction table: {err}") from None
        except UnicodeDecodeError as err:
            raise UsageError(f"--friction table: {not_utf8(rest, err)}") from None
    if name not in FRICTION_LAWS:
        raise UsageError(f"--friction: unknown law {name!r}; choose one of "
                         f"{', '.join(FRICTION_LAWS)}")
    law = FRICTION_LAWS[name]
    values = {}
    for item in filter(None, rest.split(",")):
        key, sep, value = item.partition("=")
        if not sep or key not in law.parameter_names():
            raise UsageError(f"--friction: {name} takes {', '.join(law.parameter_names())} "
                             f"as key=value, got {item!r}")
        try:
            values[key] = float(value)
        except ValueError:
            raise UsageError(f"--friction: {key} must be a number, got {value!r}") from None
    try:
        return law(**values)
    except (ValueError, TypeError) as err:
        raise UsageError(f"--friction: {err}") from None


def chain_params(args, n_osc: int, **fields) -> ChainParams:
    """The chain of a command: `n_osc`, `fields` (v_d, xi) and the chain
    options; a --chain file overrides them, then --mistuning draws the stiffness.

    **Raises:**

    `UsageError` or `ValidationError` (exit status 2) for a bad chain, a file
    that is not UTF-8 (named), or a chain too large for this machine's memory
    over the command's --t-end (`check_footprint`), refused before it is built.
    """
    lattice = getattr(args, "lattice", None)
    horizon = _typed_horizon(args)
    if lattice is None:
        check_footprint(n_osc, None, horizon)
        topology = {"n_osc": n_osc, "boundary": args.boundary}
    else:
        n_lattice = lattice[0] * lattice[1]
        check_footprint(n_lattice, f"--lattice {lattice[0]}x{lattice[1]} ({n_lattice} "
                        f"oscillators)", horizon)
        topology = {"graph": Graph.lattice(*lattice, args.boundary)}
    force = getattr(args, "force", None)
    if force is not None:
        n_osc_given = n_osc if lattice is None else lattice[0] * lattice[1]
        try:
            fields["forcing"] = (Forcing(force[0], force[1]) if force[2] == 0 else
                                 Forcing.engine_order(n_osc_given, force[2], force[0], force[1]))
        except ValidationError as err:
            raise UsageError(f"--force: {err}") from None
    base = ChainParams(**topology, friction=_parse_friction(args.friction), **fields)
    params = base
    if args.chain is not None:
        try:
            params = chain_from_file(args.chain, base)
        except UnicodeDecodeError as err:
            raise UsageError(f"--chain {not_utf8(args.chain, err)}") from None
        except (ValueError, TypeError) as err:
            raise UsageError(f"--chain {err}") from None
        check_footprint(params.n_osc, f"--chain {args.chain} ({params.n_osc} oscillators)",
                        horizon)
    if params.forcing is not None and not hasattr(args, "force"):
        raise UsageError(f"--chain {args.chain}: a forced chain (force_amplitude, ...) is "
                         "taken by jaxchain response only")
    if getattr(args, "mistuning", None) is not None:
        params = mistune(params, args.mistuning, args.mistuning_seed)
    return params


def _typed_horizon(args) -> SimulationOptions | None:
    """The horizon that the command's --t-end and --transient name, for the
    estimate of `check_footprint` before the chain is built; None where the
    command has none, or where the command refuses them later itself."""
    if not hasattr(args, "t_end"):
        return None
    try:
        return SimulationOptions(t_end=args.t_end, transient=getattr(args, "transient", 0.0))
    except (ValidationError, TypeError):
        return None


def not_utf8(path, err: UnicodeDecodeError) -> str:
    """The refusal of a text file that is not UTF-8, naming it and the first byte
    that is not."""
    return (f"{path}: not UTF-8 text (byte 0x{err.object[err.start]:02x} at offset "
            f"{err.start}); save it as UTF-8")
