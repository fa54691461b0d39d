"""`jaxchain stress`: the stress matrix, every case on every solver path, verified
or failed with a specific status."""

import argparse
import time

from .._engine.solver.registry import SOLVERS
from .._studies.stress.cases import MATRIX, QUICK_MATRIX, stress_cases
from .._studies.stress.report import counts, markdown
from .._studies.stress.run import PATHS, stress
from .common import (DEFAULTS, Outputs, RunsFailed, UsageError, add_output_options,
                     add_tolerance_options, comma_list, note, positive_int, print_json,
                     show_progress)

HELP = "numerical stability on stiff and extreme cases (the stress matrix)"
DESCRIPTION = f"""\
Vary one thing at a time from the paper's defaults (eq. (7), eta_c = 0.01, N = 20,
v_d = 1.5, eps = 1e-3, the localized start of eq. (8) on a quarter of the ring):
{'; '.join(f"{k}: {', '.join(map(str, v))}" for k, v in MATRIX.items())}.
Each case runs for t in [0, 300] on each solver path ({', '.join(PATHS)}) and ends
"verified" (finite results whose physics checks hold: the energy balance along the
trajectory, and where they apply steady sliding above the stick-slip existence
limit with the linear decay rate, -xi when friction is constant, staying at exact
steady sliding, and the growth rate at the Hopf point) or "failed" with the run's
status and a hint. --quick runs the reduced matrix
({'; '.join(f"{k}: {', '.join(map(str, v))}" for k, v in QUICK_MATRIX.items())})
for t in [0, 150].

Writes <out>/stress.csv as it goes (a later run with the same --out reuses the rows
of equal settings) and <out>/stress.md, the table of docs/stress.md. Exits with
status 1 if a physics check fails or a non-finite result is reported as ok (a
defect); failures with a specific status are outcomes, not errors."""


def add_parser(sub):
    p = sub.add_parser("stress", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true", help="the reduced matrix")
    p.add_argument("--what", type=comma_list(str), default=None, metavar="W,...",
                   help=f"rows of the matrix to run, of {','.join(MATRIX)} (default all)")
    g = p.add_argument_group("solver")
    g.add_argument("--solver", type=comma_list(str), default=list(PATHS), metavar="S,...",
                   help=f"solver paths, one or a list, of {','.join(SOLVERS)} (default "
                        f"{','.join(PATHS)})")
    add_tolerance_options(g)
    g.add_argument("--max-steps", type=positive_int, default=DEFAULTS.max_steps,
                   help=f"step budget per chunk (default {DEFAULTS.max_steps})")
    add_output_options(p, resume="from the rows stored in DIR/stress.csv (those of equal "
                                 "settings)", figures=False)
    p.set_defaults(run=run)
    return p


def run(args) -> None:
    for option, values in (("--solver", args.solver), ("--what", args.what)):
        if values is not None and not values:
            raise UsageError(f"{option}: give at least one name")
    for name in args.solver:
        if name not in SOLVERS:
            raise UsageError(f"--solver: unknown solver {name!r} (choose from "
                             f"{', '.join(SOLVERS)})")
    for name in args.what or ():
        if name not in MATRIX:
            raise UsageError(f"--what: unknown row {name!r} (choose from {', '.join(MATRIX)})")
    outputs = Outputs(args, data=["stress.csv", "stress.md"])
    start = time.perf_counter()
    tolerances = {"rtol": args.rtol, "atol": args.atol, "controller": args.controller,
                  "max_steps": args.max_steps}
    cases = [c for c in stress_cases(args.quick, **tolerances)
             if args.what is None or c.what in args.what]
    rows = stress(cases, args.solver, path=outputs.path("stress.csv"),
                  progress=show_progress(args))
    table = outputs.text(markdown(rows), "stress.md")
    c = counts(rows)
    if args.json:
        keys = ("what", "value", "solver", "outcome", "status", "check", "hint")
        print_json({"cases": [{k: r[k] for k in keys} for r in rows], **c,
                    "wall_time_s": time.perf_counter() - start}, outputs)
    else:
        for r in rows:
            if r["outcome"] == "failed":
                print(f"{r['what']} = {r['value']}, {r['solver']}: {r['status']}: "
                      f"{r['hint']}")
        print(f"{c['tried']} runs: {c['verified']} verified, {c['failed_with_status']} "
              f"failed with a specific status, {c['defects']} defects")
        note(outputs.summary())
    if c["defects"]:
        raise RunsFailed(f"{c['defects']} of {c['tried']} runs failed a physics check or "
                         f"reported a non-finite result; see {table}")
