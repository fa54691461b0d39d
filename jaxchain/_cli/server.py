"""`jaxchain server status` and `jaxchain server stop`: the warm processes of this
user, shown and stopped. Standard library only: it runs at once, in the command's
own process, and never starts a warm process."""

import argparse
import contextlib
import json
import os
import signal
import sys
import time

from .parser import Parser, UsageError
from .warm import alive, enabled, states

HELP = "show or stop the warm processes that keep JAX loaded between commands"
DESCRIPTION = """\
After a first command, a warm process keeps Python, JAX, jaxchain and the compiled
programs of the commands it ran loaded, and runs the next commands of the same
environment (the same Python and installed packages, the same jaxchain sources,
the same JAX, XLA and path settings). It stops after JAXCHAIN_SERVER_IDLE seconds
(600) without a command, when jaxchain's sources or the installed packages change,
and replaces itself when it holds more than JAXCHAIN_SERVER_MAX_MB MiB (1024)
after a command. JAXCHAIN_SERVER=0 turns it off, JAXCHAIN_SERVER=1 on; unset, it
is off under CI or a batch scheduler (CI, SLURM_JOB_ID, PBS_JOBID, LSB_JOBID).

  jaxchain server status     each warm process: pid, state, idle time, memory,
                             commands served, version, environment
  jaxchain server stop       stop them all (--pid PID: one)"""

#: Seconds `_stop` waits for a warm process to end on SIGTERM (it finishes the
#: command it runs) before it kills it.
STOP_S = 10.0


def add_parser(sub):
    p = sub.add_parser("server", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    actions = p.add_subparsers(dest="action", metavar="ACTION", parser_class=Parser,
                               required=True)
    status = actions.add_parser("status", help="each warm process of this user")
    status.add_argument("--json", action="store_true",
                        help="print one JSON document (a list, one entry per process)")
    stop = actions.add_parser("stop", help="stop this user's warm processes")
    stop.add_argument("--pid", type=int, default=None,
                      help="stop only the warm process with this process id")
    stop.add_argument("--json", action="store_true",
                      help="print one JSON document: the process ids stopped")
    p.set_defaults(run=run)
    return p


def run(args) -> None:
    (_show if args.action == "status" else _stop)(args)


def _show(args) -> None:
    """Print each warm process of this user (`jaxchain._cli.warm.states`)."""
    found = states()
    if args.json:
        print(json.dumps(found))
        return
    if not found:
        where = "" if enabled() else " (JAXCHAIN_SERVER=0, or under CI or a batch scheduler)"
        print(f"no warm process of this user is running{where}")
        return
    print(f"{'pid':>8} {'state':>8} {'idle':>8} {'memory':>10} {'served':>6}  "
          f"{'version':<8} environment")
    for s in found:
        idle = "-" if s["idle_s"] is None else f"{s['idle_s']:.0f} s"
        rss = "?" if s["rss_mb"] is None else f"{s['rss_mb']:.0f} MiB"
        print(f"{s['pid']:>8} {s['state']:>8} {idle:>8} {rss:>10} {s['served']:>6}  "
              f"{s['version']:<8} {s['prefix']}")


def _stop(args) -> None:
    """Stop this user's warm processes (or the one of --pid): SIGTERM, which ends
    one after the command it runs, then SIGKILL after `STOP_S` seconds.

    **Raises:** `UsageError` when --pid names no warm process of this user."""
    found = states()
    if args.pid is not None:
        found = [s for s in found if s["pid"] == args.pid]
        if not found:
            raise UsageError(f"--pid {args.pid}: no warm process of this user has this id "
                             f"(jaxchain server status lists them)")
    for s in found:
        _signal(s, signal.SIGTERM)
    end = time.monotonic() + STOP_S
    while any(_alive(s) for s in found) and time.monotonic() < end:
        time.sleep(0.05)
    for s in found:
        _signal(s, signal.SIGKILL)
    states()  # removes the files of the killed ones
    pids = [s["pid"] for s in found]
    if args.json:
        print(json.dumps({"stopped": pids}))
    elif pids:
        print(f"stopped {len(pids)} warm process{'es' if len(pids) > 1 else ''}: "
              + ", ".join(map(str, pids)))
    else:
        print("no warm process of this user is running")


def _alive(state: dict) -> bool:
    """Whether the warm process of `state` still runs: its id, held by the process
    that started when it did (an id given to another process since is not it)."""
    return alive(state["pid"], state.get("start"))


def _signal(state: dict, sig) -> None:
    """Send `sig` to the warm process of `state`, if it still runs; never to a
    process that has its old id."""
    if _alive(state):
        with contextlib.suppress(ProcessLookupError):
            os.kill(state["pid"], sig)


def run_alone(argv: list[str]) -> int:
    """`jaxchain server ...` in this process, without JAX: its exit status (2 and
    one line for a bad option)."""
    parser = Parser(prog="jaxchain")
    add_parser(parser.add_subparsers(dest="command", parser_class=Parser))
    args = parser.parse_args(argv)
    try:
        args.run(args)
    except UsageError as err:
        print(f"jaxchain server: error: {err}", file=sys.stderr)
        return 2
    return 0
