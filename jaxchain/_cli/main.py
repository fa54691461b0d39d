"""Entry point of the `jaxchain` command."""

import sys

from . import boundaries, crosscheck, localized, work_precision
from .common import Parser, UsageError

COMMANDS = (localized, crosscheck, work_precision, boundaries)


def build_parser() -> Parser:
    parser = Parser(
        prog="jaxchain",
        description="Simulate rings of friction-excited oscillators (eq. (5) of "
                    "'Multiple spatially localized dynamical states in "
                    "friction-excited oscillator chains'). All quantities are "
                    "dimensionless, eqs. (4)-(6).")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    for command in COMMANDS:
        command.add_parser(sub)
    return parser


def main(argv=None) -> int:
    """Run the command line; returns the exit status (2 for a usage error, 1 when a
    trajectory failed, 0 otherwise)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.error("a COMMAND is required (see jaxchain --help)")
    try:
        return args.run(args)
    except UsageError as err:
        print(f"jaxchain {args.command}: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
