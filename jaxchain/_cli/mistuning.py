"""`jaxchain mistuning`: the paper's open question, what random stiffness mistuning
(Anderson localization) does to the friction-localized states."""

import argparse
import time

import numpy as np

from .._studies.mistuning.edges import EDGE_OPTIONS
from .._studies.mistuning.study import (STUDY_OPTIONS, STUDY_SIGMAS, STUDY_VD, TABLE_SIGMAS, THETAS,
                                mistuning_study)
from .._studies.mistuning.summary import failed_runs, localization_table, study_summary
from .._engine.options import SimulationOptions
from .._physics.record import chain_record
from .._plots.mistuning import plot_mistuned_states, plot_mistuning_study, plot_site_edges
from .chain import CHAIN_HELP, add_chain_options, chain_params
from .common import (Outputs, RunsFailed, UsageError, add_output_options, add_ring_options,
                     add_scheduler_option, add_solver_options, add_vd_option, cluster_client,
                     comma_list, positive_float, positive_int, report, show_progress,
                     simulation_options, smoothed_only, engine_of)

HELP = "random mistuning against the localized states (Anderson meets friction)"
DESCRIPTION = """\
The paper ends by asking how its friction-induced localization interacts with
Anderson localization, which any real chain's mistuning brings. With eta_c = 0.01
a stiffness mistuning of the same order already localizes the linear modes. This
command maps what it does to the localized states:

  - the localization factor gamma of the linear chain (transfer matrices,
    Castanier & Pierre 1995) at the band centre and at theta = pi/3 for
    sigma / eta_c = 0.25, 0.5, 1, 2, 4, with its error and the weak-disorder
    formula sigma^2 / (8 eta_c^2 sin^2 theta);
  - for each sigma / eta_c of --sigmas and each of --draws draws delta_n ~
    N(0, sigma^2) (draw d: seed d, the same normal numbers at every sigma), at
    each belt speed of --vd: the Fig. 4 staircase (eq. (8), k = 1..N excited:
    the share that keeps n_HALC = k) and basin stability from --samples random
    initial states (x in [-2, 2], x' in [0, 2], seed --sample-seed), with 95 % Wilson
    intervals, and the correlation between an oscillator being on the HALC and
    its delta_n;
  - per draw, the edges of the bistable range: the Hopf point of steady sliding
    (eigenvalues of the Jacobian), and the largest belt speed at which the
    single-site state at each oscillator survives (bisection of simulations);
    for the first --folds draws of each sigma the fold of the highest one by
    shooting and pseudo-arclength continuation;
  - the decay per cell of the single-site state's amplitudes, against the damped
    homogeneous chain at the state's frequency and against gamma there.

Each chain's runs go to <out>/chains/*.zarr as they finish, the bisection to
<out>/edges.nc after each step and the folds to <out>/folds.csv: --resume
continues a killed run (a store is reused only with equal settings). --scheduler
submits every chain's runs to a Dask cluster at once (local:N: N worker processes
here), with the same results. Writes <out>/mistuning.nc, mistuning.json,
mistuning.png (the summary), mistuning_edges.png (each single-site state's end
against its delta_n) and mistuned_fig4.png (Fig. 4 of draw 0 at sigma = eta_c
beside its delta_n).

--design runs, instead, intentional mistuning by gradient (jc.design_study): on a
ring of --period oscillators, a pattern |delta_n| <= --budget that lowers (mean
kept, and mean free) or raises the highest fold of the single-site states, with
implicit gradients checked by finite differences and each optimum's fold checked
by simulation on both sides; against the A-B pattern and 8 random draws, and the
patterns tiled on the ring of --n-osc by simulation. Writes <out>/design.json and
design.png."""


def add_parser(sub):
    p = sub.add_parser("mistuning", help=HELP, description=DESCRIPTION + "\n\n" + CHAIN_HELP,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    g = p.add_argument_group("model (eq. (5) of the paper; other parameters eq. (7))")
    add_ring_options(g)
    add_chain_options(g, mistuning=False)
    g = p.add_argument_group("study")
    g.add_argument("--sigmas", type=comma_list(float), default=list(STUDY_SIGMAS),
                   metavar="S,S,...", help="sigma / eta_c of the draws (default "
                   f"{','.join(f'{s:g}' for s in STUDY_SIGMAS)})")
    g.add_argument("--draws", type=positive_int, default=8, metavar="D",
                   help="mistuning draws per sigma > 0 (default 8)")
    add_vd_option(g, list(STUDY_VD), "belt speeds of the staircase and basin stability")
    g.add_argument("--samples", type=int, default=8, metavar="S",
                   help="random initial states per chain and belt speed (default 8)")
    g.add_argument("--sample-seed", type=int, default=0, metavar="K",
                   help="seed of the JAX PRNG key of the random initial states (default 0)")
    g.add_argument("--folds", type=int, default=1, metavar="F",
                   help="draws per sigma whose upper edge is refined by shooting "
                        "(default 1)")
    g.add_argument("--t-end", type=positive_float, default=STUDY_OPTIONS.t_end, metavar="T",
                   help=f"final time of each run (default {STUDY_OPTIONS.t_end:g})")
    g.add_argument("--transient", type=float, default=STUDY_OPTIONS.transient, metavar="T",
                   help=f"classify after this time (default {STUDY_OPTIONS.transient:g})")
    g.add_argument("--edge-t-end", type=positive_float, default=EDGE_OPTIONS.t_end,
                   metavar="T", help="final time of each simulation of the bisection of "
                   f"the upper edges (default {EDGE_OPTIONS.t_end:g}; the state is judged "
                   "over the last fifth)")
    g = p.add_argument_group("intentional mistuning by gradient (--design)")
    g.add_argument("--design", action="store_true",
                   help="instead of the study: intentional mistuning by gradient on a "
                        "ring of --period oscillators within --budget, lowering and "
                        "raising the highest fold, against the A-B pattern and random "
                        "draws")
    g.add_argument("--budget", type=positive_float, default=0.05, metavar="B",
                   help="largest |delta_n| of the design (default 0.05)")
    g.add_argument("--period", type=positive_int, default=4, metavar="P",
                   help="oscillators in one period of the designed pattern (default 4)")
    add_solver_options(p.add_argument_group("solver of the simulations"))
    add_scheduler_option(p)
    add_output_options(p, resume="the stores in DIR (a killed run)")
    p.set_defaults(run=run)
    return p


def run(args) -> None:
    smoothed_only(args, "the study places its belt speeds at the smoothed model's Hopf "
                        "points and differentiates it")
    if args.design:
        return _run_design(args)
    if not 0 <= args.transient < args.t_end:
        raise UsageError(f"--transient must lie in [0, t_end = {args.t_end:g}), got "
                         f"{args.transient:g}")
    params = chain_params(args, args.n_osc, v_d=1.5)
    if args.resume and args.overwrite:
        raise UsageError("--resume and --overwrite exclude each other")
    outputs = Outputs(args, data=["mistuning.json", "mistuning.nc", "chains"],
                      figures=["mistuning", "mistuning_edges", "mistuned_fig4"])
    start = time.perf_counter()
    with cluster_client(args) as client:
        study = mistuning_study(
            params, args.sigmas, args.draws, v_d=args.vd, n_samples=args.samples,
            key=args.sample_seed, n_folds=args.folds,
            engine=engine_of(args, simulation_options(args), params),
            options=simulation_options(args),
            edge_options=SimulationOptions(t_end=args.edge_t_end,
                                           transient=0.8 * args.edge_t_end),
            out=args.out, resume=args.resume or outputs.again,
            overwrite=args.overwrite, client=client,
            progress=show_progress(args))
    table = localization_table(float(params.eta_c), TABLE_SIGMAS, THETAS)
    wall = time.perf_counter() - start
    outputs.path("mistuning.nc")  # written by the study
    outputs.figure(plot_mistuning_study(study), "mistuning")
    outputs.figure(plot_site_edges(study), "mistuning_edges")
    shown = 1.0 if 1.0 in study["sigma"].values else float(study["sigma"].values[-1])
    outputs.figure(plot_mistuned_states(study, shown, 0, 1.5), "mistuned_fig4")
    s = study_summary(study) | {"localization_factor": table, "chain": chain_record(params),
                                "wall_time_s": wall, "solver": args.solver, "eps": args.eps}
    report(s, outputs, "mistuning.json", args.json, _print_summary, wall)
    failed = failed_runs(study)
    if failed:
        raise RunsFailed(f"{failed} runs failed; they are left out of the shares "
                         f"(status in {outputs.path('mistuning.nc')})")


def _print_summary(s: dict) -> None:
    print("localization factor of the linear chain (gamma per cell, +- error; "
          "weak-disorder formula):")
    for r in s["localization_factor"]:
        print(f"  sigma/eta_c {r['sigma_over_eta_c']:g}, theta {r['theta']:.4f}: "
              f"{r['gamma']:.5f} +- {r['error']:.1e} ({r['weak_disorder']:.5f}, "
              f"{r['deviation_in_errors']:+.1f} errors)")
    for r in s["sigmas"]:
        stair = ", ".join(f"{v:g}: {f:.2f}" for v, f in zip(r["v_d"], r["staircase_fraction"]))
        basin = ", ".join(f"{v:g}: {f:.2f}/{g:.2f}" for v, f, g in
                          zip(r["v_d"], r["basin_stability_vibrating"],
                              r["basin_stability_localized"]))
        e = r["upper_edge"]
        edge = (f"{e['mean']:.4f} +- {e['std']:.4f} [{e['min']:.4f}, {e['max']:.4f}]"
                if e["count"] else "none found")
        print(f"sigma/eta_c = {r['sigma_over_eta_c']:g}: staircase kept {stair}; "
              f"random starts vibrating/localized {basin}; upper edge {edge}")
    print(f"single-site state: decay per cell {s['damped_chain_decay']:.3f} on the damped "
          f"homogeneous chain (period {s['state_period']:.4f})")


def _run_design(args) -> None:
    """`--design`: `design_study`, its JSON and figure."""
    from .._studies.mistuning.design_study import design_study
    from .._plots.mistuning import plot_mistuning_design

    if not 0 < args.budget < 1:
        raise UsageError(f"--budget must lie in (0, 1), got {args.budget:g}")
    if args.period < 2 or args.n_osc % args.period:
        raise UsageError(f"--period must be >= 2 and divide --n-osc {args.n_osc}, got "
                         f"{args.period}")
    params = chain_params(args, args.period, v_d=1.5)
    outputs = Outputs(args, data=["design.json"], figures=["design"])
    start = time.perf_counter()
    result = design_study(params, budget=args.budget, chain_n_osc=args.n_osc,
                          engine=engine_of(args, simulation_options(args), params),
                          progress=show_progress(args))
    result |= {"wall_time_s": time.perf_counter() - start, "chain": chain_record(params)}
    outputs.figure(plot_mistuning_design(result), "design")
    report(result, outputs, "design.json", args.json,
           lambda r: _print_design(r, params.n_osc, args.n_osc), result["wall_time_s"])
    bad = [k for k, d in result["designs"].items() if not d["simulation"]["agrees"]]
    if bad:
        raise RunsFailed(f"direct simulation disagrees with the fold of {', '.join(bad)}")


def _print_design(result: dict, ring: int, n_osc: int) -> None:
    hom = result["homogeneous_fold"]
    print(f"homogeneous ring of {ring}: highest single-site fold {hom:.6f}")
    for name, d in result["designs"].items():
        print(f"{name}: pattern {np.round(d['pattern'], 4).tolist()}, highest fold "
              f"{d['edge']:.6f} ({d['moved_by']:+.6f}); gradient vs finite differences "
              f"{d['gradient_check']['largest_difference']:.1e}; simulation "
              f"{'agrees' if d['simulation']['agrees'] else 'DISAGREES'}")
    rand = [r["edge"] for r in result["random"] if r["edge"] is not None]
    print(f"A-B: {result['ab']['edge']:.6f}; random draws: {min(rand):.6f} to "
          f"{max(rand):.6f}; tiled on N = {n_osc} (simulation): "
          + ", ".join(f"{k} {v:.4f}" for k, v in result["chain_edges"]["edge"].items()
                      if not k.startswith("random")))
