"""`jaxchain snake`: the branches of the chain's localized periodic states over the
belt speed, with their stability and bifurcations."""

import argparse
import dataclasses
import time
from pathlib import Path

from .._bifurcation.shooting import Shooting
from .._bifurcation.branches import SLIDING_PASSES
from .._studies.snake.branch import SNAKE_CONTINUATION
from .._studies.snake.run import localized_branches
from .._studies.snake.starts import SNAKE_START, check_starts, default_sites, default_starts
from .._plots.snake import plot_snake
from .chain import CHAIN_HELP, add_chain_options, chain_params
from .common import (Outputs, RunsFailed, UsageError, add_output_options, add_ring_options,
                     add_solver_options, comma_list, one_belt_speed, positive_float, positive_int,
                     engine_of, engine_record, report, show_progress, simulation_options)

HELP = "continuation of the localized periodic states (the snake), with stability"
DESCRIPTION = """\
Compute the branches of the chain's periodic localized states over the belt speed,
which the paper's Fig. 3(b) only suggests by simulation ("snaking"):

  - start: eq. (8) with k oscillators excited (--sites), simulated at --vd; a
    turning point of the oscillator of largest amplitude and the time to the next
    are the guesses of shooting (diffrax, Levenberg-Marquardt of optimistix, phase
    condition x_n'(0) = 0), and where it fails, the turning points where the
    state comes back closest after one turn (close recurrences); an irregular
    state does not converge and is reported; a start whose state is not periodic,
    or has another number of sites on the HALC than it excites, is simulated
    again at --vd -+ 0.1 and followed from there; one that still has no orbit
    with its own number of sites, and whose eq. (8) state a symmetry of the ring
    fixes (an odd block: the reflection about its centre), is simulated at --vd,
    then --vd -+ 0.1, inside that symmetry's fixed subspace, where an orbit
    unstable only across it attracts;
  - Floquet multipliers from the monodromy matrix (forward mode through the
    solver), the trivial one deflated (the flow direction); its distance from 1
    and the multipliers' change at 100x tighter tolerances are reported;
  - pseudo-arclength continuation of each branch both ways in v_d through its
    folds, within [--vd-min, --vd-max] and --max-points points each way;
  - folds of limit cycles, branch points, period doubling and Neimark-Sacker
    points, classified by the critical multiplier and located by bisection along
    the branch;
  - at each branch point, branch switching: the other branch through it, along
    the kernel direction of the continuation's Jacobian that the followed branch
    does not take, or, where that step fails (a symmetric ring's branch points,
    with a larger kernel), the orbits that deflation finds 0.01 to either side;
    each followed away from it (--no-switch skips it);
  - with --deflate M, deflation (Farrell, Birkisson and Funke 2015) from each
    start's eq. (8) state, a start whose simulated state is not periodic included:
    up to M further periodic orbits at --vd, none of those found before, each
    followed as a branch of its own, so that branches that meet no followed one
    are found too;
  - which branches meet (the same orbit up to the chain's symmetries), and for
    each n whether the orbits with n and n + 1 sites on the HALC connect (one
    set of branches, joined where they meet, carries both), the stable ones
    too;
  - direct simulation just inside and outside each end of each stable range
    (--no-simulation skips it).

Writes <out>/snake.png, <out>/snake.json and each branch to
<out>/snake/branch_k<k>.nc as it finishes; a second run with the same settings
reads the stored branches back (--resume). --sweep DIR/sweep.zarr draws the points
of a `jaxchain sweep` underneath. The solver options set the simulations (the
starts and the checks); shooting keeps its own tight tolerances.

With --engine exact, the exact stick/slip switch model throughout: simulations on
the exact engine, shooting by Newton's method with the exact engine's derivative
through every switch (its saltation matrices), then the damped Newton method
(Armijo backtracking) where Newton's method fails, and the exact Floquet multipliers
(stick phases give multipliers at zero); their accuracy is checked at 100x looser
tolerances, the exact engine's being near rounding already (1e-12)."""


def _start(text: str):
    """A start of --sites: a number, or a name (checked against the chain later)."""
    text = text.strip()
    try:
        return int(text)
    except ValueError:
        return text


def add_parser(sub):
    p = sub.add_parser("snake", help=HELP, description=DESCRIPTION + "\n\n" + CHAIN_HELP,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    g = p.add_argument_group("model (eq. (5) of the paper; other parameters eq. (7))")
    add_ring_options(g)
    add_chain_options(g)
    g = p.add_argument_group("continuation")
    g.add_argument("--vd", type=one_belt_speed, default=1.5, metavar="V",
                   help="the belt speed where the states are found by simulation, one "
                        "value (default 1.5); a start whose simulated state is not periodic "
                        "there, or has another number of sites on the HALC than it excites, "
                        "is simulated again at V - 0.1 and V + 0.1")
    g.add_argument("--sites", type=comma_list(_start), default=None, metavar="K,K,...",
                   help="the start of each branch: a number k of oscillators excited by "
                        "eq. (8) (a patch on a lattice), site:N for oscillator N alone "
                        "(0-based), or corner, edge, interior on a lattice (default 1, 2, "
                        "4, ... up to N/2, and N: "
                        f"{','.join(map(str, default_sites(20)))} on the ring of 20, those "
                        "above N dropped; corner,edge,interior on a lattice); all: every k "
                        "= 1 ... N")
    g.add_argument("--vd-min", type=positive_float, default=1.0,
                   help="smallest belt speed of the branches (default 1.0)")
    g.add_argument("--vd-max", type=positive_float, default=2.2,
                   help="largest belt speed of the branches (default 2.2)")
    g.add_argument("--max-points", type=positive_int, default=SNAKE_CONTINUATION.max_points,
                   help="continuation points each way (default "
                        f"{SNAKE_CONTINUATION.max_points}), and as many again past each "
                        f"sliding point an exact branch goes through (at most "
                        f"{SLIDING_PASSES})")
    g.add_argument("--no-simulation", action="store_true",
                   help="skip the check by direct simulation at the ends of stable ranges")
    g.add_argument("--deflate", type=int, default=0, metavar="M",
                   help="at --vd, up to M further periodic orbits from the eq. (8) state "
                        "of each start by deflation (every orbit found so far, its copies "
                        "under the ring's symmetries and steady sliding deflated), each "
                        "followed as a branch of its own (default 0: none)")
    g.add_argument("--workers", type=positive_int, default=1, metavar="W",
                   help="processes that follow the starts' branches side by side, one "
                        "core each (default 1: one after another); the branches are the "
                        "same either way")
    g.add_argument("--no-switch", action="store_true",
                   help="do not follow the other branch at each branch point (branch "
                        "switching along the kernel direction the branch does not take)")
    g.add_argument("--sweep", type=Path, default=None, metavar="STORE",
                   help="a sweep store (jaxchain sweep's sweep.zarr) to draw underneath")
    add_solver_options(p.add_argument_group("solver of the simulations"))
    add_output_options(p, resume="from the branches stored in DIR/snake (those of equal "
                                 "settings)")
    p.set_defaults(run=run)
    return p


def run(args) -> None:
    params = chain_params(args, args.n_osc, v_d=args.vd)
    asked = (default_starts(params.graph) if args.sites is None else
             list(range(1, params.n_osc + 1)) if args.sites == ["all"] else args.sites)
    sites = [k for k in asked if isinstance(k, str) or k <= params.n_osc]
    try:
        sites = list(check_starts(params.graph, sites))
    except ValueError as err:
        raise UsageError(f"--sites: {err}") from None
    if not args.vd_min < args.vd < args.vd_max:
        raise UsageError(f"--vd must lie between --vd-min and --vd-max, got {args.vd_min}, "
                         f"{args.vd}, {args.vd_max}")
    sweep = None
    if args.sweep is not None:
        from .._sweeps.sweep import open_sweep
        sweep = open_sweep(args.sweep)
    outputs = Outputs(args, data=["snake.json"], figures=["snake"])
    start = time.perf_counter()
    options = dataclasses.replace(SNAKE_CONTINUATION, p_min=args.vd_min, p_max=args.vd_max,
                                  max_points=args.max_points)
    # one engine, built once: the simulations' (starts and checks), and shooting
    # on its model (`Shooting.from_simulations`)
    engine = engine_of(args, simulation_options(args, t_end=SNAKE_START.t_end,
                                                transient=SNAKE_START.transient), params)
    found = localized_branches(params, sites, method=Shooting.from_simulations(engine),
                               engine=engine, continuation_options=options,
                               start_options=engine.options,
                               switch=not args.no_switch, deflate=args.deflate,
                               simulation_check=not args.no_simulation,
                               out=outputs.path("snake"), progress=show_progress(args),
                               workers=args.workers)
    outputs.figure(plot_snake(found["datasets"], sweep,
                              title=f"N = {params.n_osc}, {engine.describe()}: stable solid, "
                                    "unstable dashed"), "snake")
    s = (found["summary"] | {"wall_time_s": time.perf_counter() - start,
                            "n_osc": params.n_osc, "v_d": float(params.v_d)}
         | engine_record(engine))
    report(s, outputs, "snake.json", args.json, _print_summary, s["wall_time_s"])
    disagree = [c for b in s["branches"] for c in b.get("simulation_check", [])
                if c["agrees"] is False]
    if not s["branches"]:
        raise RunsFailed("no periodic state to continue: every start was irregular or "
                         "steady sliding")
    if disagree:
        raise RunsFailed(f"direct simulation disagrees with {len(disagree)} stability "
                         f"end(s) (simulation_check in {args.out / 'snake.json'})")


def _print_summary(s: dict) -> None:
    for b in s["branches"]:
        ranges = ", ".join(f"[{lo:.4f}, {hi:.4f}]" for lo, hi in b["stable_ranges"]) or "none"
        print(f"{b['label']} excited: {b['sites']} on the HALC where stable; stable on "
              f"{ranges}; connects to {', '.join(b['connects_to']) or 'nothing found'}")
        start = b.get("start", {}).get("v_d")
        if None not in (start, s.get("v_d")) and start != s["v_d"] and "switched" not in \
                b["label"]:
            print(f"   started at v_d = {start:g}: at {s['v_d']:g} its simulated state is "
                  "not periodic, or not with the sites it excites")
        if b.get("start", {}).get("symmetric"):
            print("   its orbit found by simulation inside the fixed subspace of its start's "
                  "symmetry")
        if b.get("stop", {}).get("low") == "closed":
            print("   closed on itself" + ("" if b["connects_to"] else
                                          " (an isola: it meets no other branch)"))
        for way, stop in b.get("stop", {}).items():
            if stop == "retraced":
                print(f"   {way} end: beyond its last fold it retraces itself (its mirror "
                      "image)")
            if stop == "hopf":
                print(f"   {way} end: its amplitude vanishes at a Hopf point of steady sliding")
        for r in b["stable_range_ends"]:
            print("   ends: " + "; ".join(f"{e['type']} at {_number(e['v_d'], '.5f')}"
                                          for e in r))
        for f in b.get("failed_switches", []):
            print(f"   switch at the branch point v_d = {f['v_d']:.5f} failed: {f['reason']}")
        for c in b.get("simulation_check", []):
            verdict = ("agrees" if c["agrees"] else "DISAGREES" if c["agrees"] is False else
                       f"undecided: growth {_number(c['expected_growth'], '.3g')} over the "
                       "horizon")
            print(f"   simulation at v_d = {_number(c['v_d'], '.4f')} ({c['side']} the "
                  f"{c['end']}): {'persists' if c['persists'] else 'lost'} ({verdict})")
    for f in s["not_periodic"]:
        print(f"k={f['excited']} excited: {f['reason']}")
    for r in s.get("deflated_on_followed", []):
        print(f"{r['start']} deflated: an orbit (energy {r['energy']:.4g}) on the branch "
              f"{r['on']}, followed already")
    for c in s.get("sites_connections", []):
        n, m = c["sites"]
        if not (c["with_n"] or c["with_n_plus_1"]):
            continue  # neither number of sites is on a branch of this run
        if not (c["with_n"] and c["with_n_plus_1"]):
            print(f"{n} and {m} sites: no orbit with {n if not c['with_n'] else m} sites "
                  "found")
            continue
        through = "; ".join(ls[0] + (f" (and {len(ls) - 1} more joined to it)" if len(ls) > 1
                                     else "") for ls in c["through"])
        print(f"{n} and {m} sites: " + (
            f"connected through {through}" + (", stable ones too" if c["stable_connected"]
                                              else ", not the stable ones")
            if c["connected"] else "not connected (no branch, nor branches that meet, "
                                   "carry both)"))


def _number(value, spec: str) -> str:
    """`value` in the format `spec`, or "-" where the study found none (None, a
    non-finite number in the JSON)."""
    return "-" if value is None else format(value, spec)
