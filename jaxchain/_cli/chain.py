"""The chain options every command takes: --boundary, --friction, --mistuning,
--mistuning-seed and --chain, and the `ChainParams` they give."""

import argparse
from pathlib import Path

from .._physics.chain import BOUNDARIES
from .._physics.friction import FRICTION_LAWS
from .._physics.params import ChainParams, mistune
from .._errors import ValidationError
from .._physics.record import chain_from_record, read_chain_file
from .common import UsageError

CHAIN_HELP = """\
The chain: --boundary ring (eq. (5) of the paper, the default), free (an open line)
or fixed (an open line tied to the ground at both ends); --friction NAME:key=value,...
with NAME one of exponential (eq. (1): mu_st, mu_d, v0; the default), stribeck
(mu_s, mu_c, v_s, delta, viscous), polynomial (c0, c1, c2, c3) or coulomb (mu), for
example --friction stribeck:mu_s=1,mu_c=0.5,v_s=0.5,delta=2,viscous=0.05 (missing
keys take the law's defaults); --mistuning SIGMA --mistuning-seed S draws the stiffnesses
1 + delta_n, delta_n normal with standard deviation SIGMA; --chain FILE reads a TOML
file of chain settings, which override the options above: n_osc, boundary, xi,
eta_c (one value per link), stiffness, load (one value per oscillator), friction =
"NAME" and the law's parameters (numbers or lists of one per oscillator),
mistuning_sigma and mistuning_seed."""


def add_chain_options(g, mistuning: bool = True) -> None:
    """--boundary, --friction, --mistuning, --mistuning-seed and --chain, in the
    argument group (or parser) `g`; without --mistuning and --mistuning-seed where
    the command draws the mistuning itself (mistuning)."""
    g.add_argument("--boundary", choices=BOUNDARIES, default="ring",
                   help="ring (eq. (5), default), free or fixed ends")
    g.add_argument("--friction", default=None, metavar="NAME:k=v,...",
                   help=f"friction law, one of {', '.join(FRICTION_LAWS)} with its "
                        "parameters (default eq. (1) of the paper, exponential)")
    if mistuning:
        g.add_argument("--mistuning", type=_non_negative, default=None, metavar="SIGMA",
                       help="standard deviation of random stiffness mistuning delta_n "
                            "(default none)")
        g.add_argument("--mistuning-seed", type=int, default=0, metavar="S",
                       help="seed of the JAX PRNG key of the mistuning draw (default 0)")
    g.add_argument("--chain", type=Path, default=None, metavar="FILE",
                   help="TOML file of chain settings (per-oscillator arrays included); "
                        "see the chain paragraph of --help")


def _non_negative(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (0 <= value < float("inf")):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text!r}")
    return value


def parse_friction(text: str | None):
    """The friction law of `--friction NAME:key=value,...` (None: eq. (1)).

    **Raises:**

    `UsageError` naming --friction for an unknown law or key, a value that is not a
    number, or parameters the law refuses.
    """
    if text is None:
        return None
    name, _, rest = text.partition(":")
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
    """The chain of a command: `n_osc`, `fields` (v_d, eps, xi) and the chain
    options; a --chain file overrides them, then --mistuning draws the stiffness.

    **Raises:**

    `UsageError` or `ValidationError` (exit status 2) for a bad chain.
    """
    base = ChainParams(n_osc=n_osc, boundary=args.boundary,
                       friction=parse_friction(args.friction), **fields)
    params = base
    if args.chain is not None:
        try:
            record = read_chain_file(args.chain)
        except ValidationError as err:
            raise UsageError(f"--chain {err}") from None
        try:
            params = chain_from_record(record, base)
        except (ValueError, TypeError) as err:
            raise UsageError(f"--chain {args.chain}: {err}") from None
    if getattr(args, "mistuning", None) is not None:
        params = mistune(params, args.mistuning, args.mistuning_seed)
    return params
