"""`jaxchain figure NAME`: one of the paper's scenes (Figs. 4-10), at full size or
reduced, as a PNG and an xarray Dataset."""

import argparse
import time

import numpy as np

from .._studies.scenes import (PAPER_FIGURES, PAPER_SOLUTIONS, orbit_diagram_scene,
                               phase_portrait_scene, time_delay_scene, time_series_scene)
from .._sweeps.ensemble import ensemble
from .._physics.initial import localized_family
from .._physics.params import ChainParams
from .._plots.dynamics import (plot_orbit_diagram, plot_phase_portraits,
                               plot_states_and_orbits, plot_time_delays, plot_time_series)
from .._plots.localized import plot_localized_states
from .._engine.status import status_names
from .._physics.forces import DEFAULT_EPS
from .._physics.record import chain_record
from .chain import CHAIN_HELP, add_chain_options, chain_params
from .common import (Outputs, RunsFailed, add_output_options, add_solver_options,
                     add_vd_option, engine_of, engine_record, engine_text, note,
                     positive_float, print_json, show_progress,
                     simulation_options, smoothed_only)

#: Each figure: its belt speed, initial conditions and what it shows.
#: --quick: a ring of 8 over [0, 600], observed over [400, 600] (Fig. 5: [0, 100]),
#: in chunks of 50 (the Lyapunov exponent's batch means need several).
QUICK = {"n_osc": 8, "t_end": 600.0, "transient": 400.0, "t_series": 100.0,
         "chunk_length": 50.0}
FULL = {"n_osc": 20, "t_end": 15000.0, "transient": 10000.0, "t_series": 300.0,
        "chunk_length": 250.0}
#: Figures whose --json lists the classified solutions.
CLASSIFIED = ("6", "8", "9", "10")

HELP = "one of the paper's scenes, Figs. 4-10, as PNG and Dataset"
DESCRIPTION = """\
Run one of the paper's scenes and draw its figure. NAME is the figure number:

""" + "\n".join(f"  {k:>2}  v_d = {v:g}, {ics}: {what}"
                for k, (v, ics, what) in PAPER_FIGURES.items()) + """

At full size (the paper's: N = 20, t_end = 15000, the window [10000, 15000]);
--quick runs a ring of 8 over [0, 600], observed over [400, 600].

Figs. 6, 8, 9 and 10 classify each state as periodic or irregular from two
independent signals, the spread of its time delays (the paper's criterion) and
its largest Lyapunov exponent against its stated error; where they disagree the
state is "undecided". Each scene observes only what it shows.

Writes <out>/figure<NAME>.nc (xarray Dataset with all parameters as attributes)
and <out>/figure<NAME>.png."""


def add_parser(sub):
    p = sub.add_parser("figure", help=HELP, description=DESCRIPTION + "\n\n" + CHAIN_HELP,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("name", choices=list(PAPER_FIGURES), metavar="NAME",
                   help="figure number: " + ", ".join(PAPER_FIGURES))
    p.add_argument("--quick", action="store_true",
                   help="a reduced scene: N = 8, t in [0, 600], window [400, 600]")
    g = p.add_argument_group("model and integration (other parameters eq. (7))")
    g.add_argument("--eps", type=positive_float, default=DEFAULT_EPS,
                   help=f"tanh smoothing velocity (default {DEFAULT_EPS:g})")
    add_vd_option(g, None, "belt speeds, each drawn in turn (default the figure's own, "
                           "that of the paper)")
    add_chain_options(g)
    add_solver_options(p.add_argument_group("solver"))
    add_output_options(p)
    p.set_defaults(run=run)
    return p


def _scene(name: str, size: dict, params: ChainParams, engine, progress):
    """The Dataset and the figure of scene `name`, run by `engine` (figures 5-10: the
    smoothed one)."""
    ics = PAPER_FIGURES[name][1]
    solutions = [k for k in PAPER_SOLUTIONS if k <= params.n_osc]
    if name == "4":
        family = localized_family(params.n_osc, ics, params.graph)
        ds = ensemble(params, [params.v_d.item()], family, engine=engine, progress=progress)
        return ds, plot_localized_states(ds)
    solver, options = engine.solver, engine.options
    if name == "5":
        ds = time_series_scene(params, 2, ics, size["t_series"], solver=solver,
                               progress=progress)
        return ds, plot_time_series(ds)
    if name == "6":
        ds = time_delay_scene(params, solutions, ics, solver, options, progress=progress)
        return ds, plot_time_delays(ds)
    if name == "7":
        ds = phase_portrait_scene(params, solutions, None, ics, solver=solver,
                                  options=options, progress=progress)
        return ds, plot_phase_portraits(ds)
    ds = orbit_diagram_scene(params, None, ics, solver, options, progress=progress)
    return ds, (plot_orbit_diagram(ds) if name == "8" else plot_states_and_orbits(ds))


def _stem(name: str, v_d: float, paper_vd: float) -> str:
    """The file name of a figure at belt speed v_d: figureN at the paper's speed."""
    return f"figure{name}" if v_d == paper_vd else f"figure{name}_vd{v_d:g}"


def run(args) -> None:
    if args.name != "4":
        smoothed_only(args, f"figure {args.name} observes time series, peak times or "
                            "Lyapunov exponents, which the exact engine does not record")
    size = QUICK if args.quick else FULL
    paper_vd, ics, _ = PAPER_FIGURES[args.name]
    speeds = args.vd or [paper_vd]
    stems = [_stem(args.name, v, paper_vd) for v in speeds]
    outputs = Outputs(args, data=[f"{stem}.nc" for stem in stems], figures=stems)
    options = simulation_options(args, t_end=size["t_end"], transient=size["transient"],
                                 chunk_length=size["chunk_length"])
    reports, status = [], []
    start = time.perf_counter()
    for v_d, stem in zip(speeds, stems):
        params = chain_params(args, size["n_osc"], v_d=v_d)
        engine = engine_of(args, options, params)
        ds, fig = _scene(args.name, size, params, engine, show_progress(args))
        ds.attrs |= {"figure": args.name, "quick": int(args.quick)}
        outputs.dataset(ds, f"{stem}.nc")
        outputs.figure(fig, stem)
        states = status_names(np.ravel(ds["status"].values)).tolist()
        status += states
        report = {"v_d": v_d}
        if args.name in CLASSIFIED:
            report["solutions"] = [
                {"n_excited": int(r["solution"]), "n_halc": int(r["n_halc"]),
                 "class": str(r["class"].values),
                 "class_delays": str(r["class_delays"].values),
                 "class_lyapunov": str(r["class_lyapunov"].values),
                 "lyapunov": float(r["lyapunov"]),
                 "lyapunov_error": float(r["lyapunov_error"]),
                 "delay_spread": float(r["delay_spread"]), "status": s}
                for r, s in zip((ds.isel(solution=i) for i in range(ds.sizes["solution"])),
                                states)]
        reports.append(report)
    wall = time.perf_counter() - start
    if args.json:
        print_json({"figure": args.name, "runs": reports, "ics": ics,
                    "n_osc": params.n_osc, "chain": chain_record(params), **engine_record(engine),
                    "quick": args.quick, "wall_time_s": wall},
                   outputs)
    else:
        for report in reports:
            print(f"Fig. {args.name}{' (quick)' if args.quick else ''}: "
                  f"v_d = {report['v_d']:g}, N = {params.n_osc}, {engine_text(engine)}, "
                  f"ics = {ics}")
            if args.name in CLASSIFIED:
                print(f"{'excited':>7} {'n_HALC':>6} {'class':>10} {'delays':>9} "
                      f"{'Lyapunov':>9} {'lambda':>10} {'error':>9} {'spread':>9}")
                for s in report["solutions"]:
                    print(f"{s['n_excited']:7d} {s['n_halc']:6d} {s['class']:>10} "
                          f"{s['class_delays']:>9} {s['class_lyapunov']:>9} "
                          f"{s['lyapunov']:10.2e} {s['lyapunov_error']:9.1e} "
                          f"{s['delay_spread']:9.2e}")
        note(f"wall time {wall:.1f} s (compilation included); {outputs.summary()}")
    failed = [s for s in status if s != "ok"]
    if failed:
        raise RunsFailed(f"{len(failed)} of {len(status)} trajectories failed "
                         f"({', '.join(sorted(set(failed)))})")
