"""`jaxchain work-precision`: error against run time for every solver, tolerance and
eps, against the non-smooth reference."""

import argparse
import time

from .._engine.solver.controller import CONTROLLERS
from .._plots.work_precision import plot_work_precision
from .._engine.solver.registry import SOLVERS
from .._studies.work_precision import (SCENES, WP_EPS, WP_RTOLS, WP_SOLVERS, recommend,
                               split_method, work_precision)
from .common import (DEFAULTS, Outputs, RunsFailed, UsageError, add_output_options,
                     comma_list, note, positive_int, print_json)
from .._engine.status import Status

HELP = "error against run time of every solver and eps (work-precision diagram)"
DESCRIPTION = f"""\
Measure error against wall time for the diffrax solvers {', '.join(WP_SOLVERS)}
(kencarp4 is IMEX with the friction force implicit; ros34pw2 a Rosenbrock-W method,
linearly implicit in the diagonal friction Jacobian), rtol = 1e-3 ... 1e-10 (atol =
rtol/100) and eps = 1e-1 ... 1e-5, on two scenes at v_d = 1.5: the single
oscillator (window [200, 400]) and the chain of N = 20 with one oscillator excited
(eq. (8), window [1000, 1500]). Errors are measured against the event-driven
non-smooth reference: on the amplitudes and E over the window, and on the
trajectory at t = 20, before it diverges. Compilation is timed apart from the run.
scipy's LSODA and Radau, and the exact engine (the stick/slip switch model: the
reference at looser tolerances, method "exact" in the CSV) are outside points.

Writes <out>/work_precision.csv as it goes, each row with a hash of everything
that determines it (a later run with the same --out reuses only rows of equal
settings and computes the rest), and <out>/work_precision_<scene>.png for the runs
asked for, and prints the fastest settings for 1 % and 0.1 % amplitude error. A
failed run is recorded with its status and makes the command exit with status 1.
Use --scenes, --solver, --rtol and --eps to run part of it."""


def add_parser(sub):
    p = sub.add_parser("work-precision", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenes", type=comma_list(str), default=list(SCENES), metavar="S,S",
                   help=f"scenes (default {','.join(SCENES)})")
    p.add_argument("--solver", type=comma_list(str), default=list(WP_SOLVERS), metavar="S,...",
                   help=f"diffrax solvers, one or a list, of {','.join(SOLVERS)}, each optionally "
                        f"with /CONTROLLER, of {','.join(CONTROLLERS)}, for example "
                        f"ros34pw2/diffrax (default {','.join(WP_SOLVERS)}, with the "
                        f"default controller, pi)")
    p.add_argument("--rtol", type=comma_list(float), default=list(WP_RTOLS), metavar="R,...",
                   help="relative tolerances, one or a list (default 1e-3,...,1e-10; atol "
                        "is rtol/100)")
    p.add_argument("--eps", type=comma_list(float), default=list(WP_EPS), metavar="E,...",
                   help="smoothing eps values (default 1e-1,...,1e-5)")
    p.add_argument("--max-steps", type=positive_int, default=DEFAULTS.max_steps,
                   help=f"step budget per chunk of {DEFAULTS.chunk_length:g} time units "
                        f"(default {DEFAULTS.max_steps})")
    p.add_argument("--no-scipy", action="store_true", help="leave out scipy's points")
    add_output_options(p, resume="from the rows stored in DIR/work_precision.csv (those "
                                 "of equal settings)")
    p.set_defaults(run=run)
    return p


def run(args) -> None:
    for name in args.scenes:
        if name not in SCENES:
            raise UsageError(f"--scenes: unknown scene {name!r} (choose from "
                             f"{', '.join(SCENES)})")
    for name in args.solver:
        solver, controller = split_method(name)
        if solver not in SOLVERS or controller not in CONTROLLERS:
            raise UsageError(f"--solver: unknown solver {name!r} (choose from "
                             f"{', '.join(SOLVERS)}, each optionally with /CONTROLLER, "
                             f"one of {', '.join(CONTROLLERS)})")
    for option, values in (("--rtol", args.rtol), ("--eps", args.eps)):
        if not values or not all(0 < v < 1 for v in values):
            raise UsageError(f"{option}: values must lie in (0, 1), got {values}")
    outputs = Outputs(args, data=["work_precision.csv"],
                      figures=[f"work_precision_{scene}" for scene in args.scenes])
    csv_path = outputs.path("work_precision.csv")
    start = time.perf_counter()

    def report(message):
        if not args.no_progress:
            note(f"[{time.perf_counter() - start:7.1f} s] {message}")

    rows = work_precision(csv_path, args.scenes, args.solver, args.rtol, args.eps,
                          scipy=not args.no_scipy, max_steps=args.max_steps,
                          progress=report)
    advice = {}
    for scene in args.scenes:
        outputs.figure(plot_work_precision(rows, scene), f"work_precision_{scene}")
        for target in (1e-2, 1e-3):
            best = recommend(rows, scene, target)
            advice[f"{scene} {target:g}"] = None if best is None else {
                "solver": best["method"], "eps": float(best["eps"]),
                "rtol": float(best["rtol"]), "atol": float(best["atol"]),
                "wall_s": float(best["wall_s"]),
                "amplitude_error": float(best["amplitude_error"])}
    failed = sum(r["status"].split(":")[0] not in (Status.ok.name, Status.not_run.name)
                 for r in rows)
    if args.json:
        print_json({"recommended": advice, "runs": len(rows), "failed_runs": failed,
                    "wall_time_s": time.perf_counter() - start}, outputs)
    else:
        for key, best in advice.items():
            scene, target = key.split()
            text = ("no run reached it, confirmed by a run at rtol/10" if best is None else
                    f"{best['solver']}, eps {best['eps']:g}, rtol {best['rtol']:g}: "
                    f"{best['wall_s']:.3g} s, error {100 * best['amplitude_error']:.3f} %")
            print(f"{scene}, amplitude error < {100 * float(target):g} %: {text}")
        print(f"{len(rows)} runs ({failed} failed, recorded)")
        note(outputs.summary())
    if failed:
        raise RunsFailed(f"{failed} of {len(rows)} runs failed; they are recorded with "
                         f"their status in {csv_path}")
