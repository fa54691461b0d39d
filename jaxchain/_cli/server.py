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
from .warm import alive, enabled, installation, states

HELP = "show or stop the warm processes that keep JAX loaded between commands"
DESCRIPTION = """\
After a first command, a warm process keeps Python, JAX, jaxchain and the compiled
programs of the commands it ran loaded, and runs the next commands of the same
settings: the same Python and installed packages, the same jaxchain sources, the
same environment variables (but those of the terminal and the login session),
resource limits, nice value and CPU affinity. A command of other settings runs
in its own process and starts a warm process of its own settings, at most
JAXCHAIN_SERVER_MAX_PROCESSES (4) per user. A command with a CPU-time or memory
limit (ulimit -t, -v, -d) always runs in its own process. A warm process stops
after JAXCHAIN_SERVER_IDLE seconds (600) without a command, when jaxchain's
sources or the installed packages change, and replaces itself when it holds
more than JAXCHAIN_SERVER_MAX_MB MiB (1024) after a command. JAXCHAIN_SERVER=0
turns it off, JAXCHAIN_SERVER=1 on; unset, it is off under CI or a batch
scheduler (CI, SLURM_JOB_ID, PBS_JOBID, LSB_JOBID).

  jaxchain server status     each warm process of this user: pid, state, idle
                             time, memory, commands served, version, environment
  jaxchain server stop       stop this installation's warm processes, after the
                             command each one runs (--all: every one of this
                             user; --pid PID: one; --kill: without waiting)"""

#: Seconds `_stop` waits for a warm process that runs no command to end on
#: SIGTERM before it kills it (it ends within half a second unless it hangs).
STOP_S = 10.0


def add_parser(sub):
    p = sub.add_parser("server", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    actions = p.add_subparsers(dest="action", metavar="ACTION", parser_class=Parser,
                               required=True)
    status = actions.add_parser("status", help="each warm process of this user")
    status.add_argument("--json", action="store_true",
                        help="print one JSON document (a list, one entry per process)")
    stop = actions.add_parser("stop", help="stop this installation's warm processes")
    stop.add_argument("--pid", type=int, default=None,
                      help="stop only the warm process with this process id")
    stop.add_argument("--all", action="store_true",
                      help="stop every warm process of this user, of any installation of "
                           "jaxchain (by default, only those of this Python environment "
                           "and jaxchain package)")
    stop.add_argument("--kill", action="store_true",
                      help="kill a warm process that runs a command at once, its command "
                           "with it, instead of waiting until the command has finished")
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
        where = ("" if enabled() else " (JAXCHAIN_SERVER=0, under CI or a batch scheduler, "
                 "or a CPU-time or memory limit)")
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
    """Stop this installation's warm processes (`installation`; every one of this
    user with --all, the one of --pid): SIGTERM, after which each takes no more
    commands and ends once the command it runs has finished, its outputs
    written; this waits for that, saying so on standard error (with --kill, one
    that runs a command is killed at once). One that runs no command and has
    not ended after `STOP_S` seconds (hung) is killed.

    **Raises:** `UsageError` when --pid names no warm process of this user."""
    found = states()
    if args.pid is not None:
        found = [s for s in found if s["pid"] == args.pid]
        if not found:
            raise UsageError(f"--pid {args.pid}: no warm process of this user has this id "
                             f"(jaxchain server status lists them)")
    elif not args.all:
        here = installation()
        found = [s for s in found if all(s.get(k) == v for k, v in here.items())]
    for s in found:
        _signal(s, signal.SIGTERM)
    told: set = set()
    quiet = time.monotonic()  # since when each one is seen running no command
    while True:
        now = {s["pid"]: s for s in states()}
        left = [s for s in found if _alive(s)]
        if not left:
            break
        busy = [s for s in left if now.get(s["pid"], s)["state"] == "busy"]
        if busy:
            quiet = time.monotonic()
        for s in busy:
            if args.kill:
                _signal(s, signal.SIGKILL)
            elif s["pid"] not in told:
                told.add(s["pid"])
                command = " ".join(now.get(s["pid"], s).get("command") or [])
                print(f"jaxchain server: waiting for warm process {s['pid']} to finish "
                      f"'jaxchain {command}' (--kill ends it now)", file=sys.stderr, flush=True)
        if time.monotonic() - quiet > STOP_S:
            for s in left:
                _signal(s, signal.SIGKILL)
        time.sleep(0.05)
    states()  # removes the files of the killed ones
    pids = [s["pid"] for s in found]
    if args.json:
        print(json.dumps({"stopped": pids}))
    elif pids:
        print(f"stopped {len(pids)} warm process{'es' if len(pids) > 1 else ''}: "
              + ", ".join(map(str, pids)))
    else:
        print("no warm process of this installation is running" if not args.all else
              "no warm process of this user is running")


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
    except KeyboardInterrupt:  # while waiting: the processes end after their command
        print("jaxchain server: error: interrupted (the warm processes signalled end after "
              "their command)", file=sys.stderr)
        return 130
    return 0
