"""`jaxchain boundaries`: the Hopf and fold belt speeds that bound the bistable range,
for one oscillator and for the ring."""

import argparse
import time

from .._bifurcation.shooting import Shooting
from .._engine.options import SimulationOptions
from .._studies.bistable_range import (BISTABLE_RATIO_VALUES, BISTABLE_XI_VALUES,
                                       FIG3A_OPTIONS, bistable_range, fig3a_simulations)
from .._plots.bifurcation import plot_bistable_region, plot_limit_cycle_branch
from .chain import CHAIN_HELP, add_chain_options, chain_params
from .common import (Outputs, RunsFailed, UsageError, add_output_options, add_ring_options,
                     add_solver_options, comma_list, engine_of, param_default, positive_float, report,
                     show_progress, simulation_options)

HELP = "Hopf and fold belt speeds of the bistable range (gradients, continuation)"
DESCRIPTION = """\
Compute the edges of the bistable range of belt speeds, where steady sliding and
stick-slip are both stable (the paper brackets it by simulation, 1.1 < v_d < 1.8):

  - the Hopf point of steady sliding: Newton's method (optimistix) on the largest
    growth rate Re(lambda)(v_d) of the Jacobian (jax.jacfwd), for every Fourier
    mode of the ring, against the analytic v0 ln((mu_st - mu_d)/(2 xi v0)); the
    first Lyapunov coefficient says whether it is subcritical;
  - the fold of the single oscillator's limit cycle: shooting (diffrax + Newton),
    Floquet multipliers from the monodromy matrix (forward-mode through the
    solver), pseudo-arclength continuation from the Hopf point through the fold,
    then the fold's extended (Moore-Spence) system; compared with the existence
    limit of the non-smooth stick-slip cycle;
  - both edges against xi and mu_st/mu_d, with derivatives by implicit
    differentiation, and the smallest xi whose window is narrower than --target
    (optax L-BFGS), checked by simulation on both sides;
  - the ring: the Hopf point of the chain and the folds of its fully
    stick-slipping in-phase and anti-phase states.

Writes <out>/bifurcation_single.png (Fig. 3(a) with simulation dots),
<out>/bistable_region.png and <out>/boundaries.json. The solver options set the
simulation dots; shooting keeps its own tight tolerances.

With --engine exact, the exact stick/slip switch model instead: its Hopf point (the
closed form) and the grazing point where the stick-slip cycle ends (Newton's method
on its defining condition, x' = v_d and x'' = 0 at the end of the slip arc), and
both against xi and mu_st/mu_d, in the JSON keys of the smoothed run's fold
(fold_vd, xi_curve, ratio_curve; boundary "grazing"), beside the closed-form
existence limit. The smoothed run reports that limit beside its fold, with the
difference."""


def add_parser(sub):
    p = sub.add_parser("boundaries", help=HELP, description=DESCRIPTION + "\n\n" + CHAIN_HELP,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    g = p.add_argument_group("model (eq. (5) of the paper; other parameters eq. (7))")
    add_ring_options(g)
    g.add_argument("--xi", type=positive_float, default=param_default("xi"),
                   help=f"damping ratio (default {param_default('xi'):g})")
    add_chain_options(g)
    g = p.add_argument_group("analysis")
    g.add_argument("--target", type=positive_float, default=0.5,
                   help="design: the bistable window width to stay below (default 0.5)")
    g.add_argument("--xi-values", type=comma_list(float), default=list(BISTABLE_XI_VALUES),
                   metavar="X,X,...", help="damping ratios of the two-parameter curves "
                   f"(default {','.join(map(str, BISTABLE_XI_VALUES))})")
    g.add_argument("--ratio-values", type=comma_list(float), default=list(BISTABLE_RATIO_VALUES),
                   metavar="R,R,...", help="values of mu_st/mu_d of the two-parameter curves "
                   f"(default {','.join(map(str, BISTABLE_RATIO_VALUES))})")
    g.add_argument("--no-ring", action="store_true", help="skip the ring")
    g.add_argument("--no-simulation", action="store_true",
                   help="skip the simulation dots of Fig. 3(a)")
    add_solver_options(p.add_argument_group("solver of the simulation dots"))
    add_output_options(p)
    p.set_defaults(run=run)
    return p


def run(args) -> None:
    params = chain_params(args, args.n_osc, xi=args.xi)
    for name in ("xi_values", "ratio_values"):
        values = getattr(args, name)
        if not values or min(values) <= 0:
            raise UsageError(f"--{name.replace('_', '-')}: give positive numbers, got {values}")
    if min(args.ratio_values) <= 1:
        raise UsageError("--ratio-values: mu_st/mu_d must be > 1 for a Hopf point")
    # one engine, built once from --engine and --eps: shooting and every analysis
    # on its model
    method = Shooting(engine_of(args, SimulationOptions(), params).for_orbits())
    _RUNS[args.engine](args, params, method)


def _run_smoothed(args, params, method: Shooting) -> None:
    """--engine smoothed: the Hopf point, the fold, their curves and the design of
    the smoothed model (`bistable_range`), with the simulation dots of Fig. 3(a)."""
    outputs = Outputs(args, data=["boundaries.json"],
                      figures=["bifurcation_single", "bistable_region"])
    progress = show_progress(args)
    start = time.perf_counter()
    # --eps smooths every analysis; the design's check keeps the default solver (the
    # solver options set the simulation dots)
    found = bistable_range(params, target=args.target, xi_values=args.xi_values,
                           ratio_values=args.ratio_values, ring=not args.no_ring,
                           method=method, progress=progress)
    s = found.summary
    sims = None if args.no_simulation else fig3a_simulations(
        params, solver=args.solver,
        options=simulation_options(args, t_end=FIG3A_OPTIONS.t_end,
                                   transient=FIG3A_OPTIONS.transient), progress=progress,
        eps=args.eps)
    fig = plot_limit_cycle_branch(found.branch, s["hopf_vd"], s["fold_vd"],
                                  float(found.fold.record.energy), sims,
                                  title=f"single oscillator (Fig. 3(a)), eps = {args.eps:g}")
    outputs.figure(fig, "bifurcation_single")
    curves = [c for c in ("xi_curve", "ratio_curve") if c in s]
    limits = [s[c]["existence_limit_nonsmooth"] for c in curves]
    mu_d = float(params.friction.mu_d) if found.curves_ratio is not None else None
    outputs.figure(plot_bistable_region(found.curves_xi, found.curves_ratio, mu_d,
                                        found.design, limits), "bistable_region")
    s |= {"wall_time_s": time.perf_counter() - start, "solver": args.solver}
    if sims is not None:
        s["simulation_energy"] = {"v_d": sims[0].tolist(), "energy": sims[1].tolist()}
    report(s, outputs, "boundaries.json", args.json, _print_summary, s["wall_time_s"])
    missing = sum(f is None for c in curves for f in s[c]["fold_vd"])
    if missing:
        raise RunsFailed(f"the fold was not found at {missing} points of the two-parameter "
                         f"curves (null in {outputs.path('boundaries.json')})")


def _run_exact(args, params, method: Shooting) -> None:
    """--engine exact: the Hopf and grazing points of the exact switch model
    (`bistable_range` on its engine), in the JSON keys of the smoothed run's fold."""
    outputs = Outputs(args, data=["boundaries.json"], figures=["bistable_region"])
    start = time.perf_counter()
    found = bistable_range(params, xi_values=sorted(args.xi_values),
                           ratio_values=sorted(args.ratio_values), method=method)
    s, curves_xi, curves_ratio = found.summary, found.curves_xi, found.curves_ratio
    mu_d = float(params.friction.mu_d) if curves_ratio is not None else None
    limits = [s[c]["existence_limit_nonsmooth"] for c in ("xi_curve", "ratio_curve") if c in s]
    outputs.figure(plot_bistable_region(curves_xi, curves_ratio, mu_d, None, limits,
                                        fold_label="grazing (exact model)"),
                   "bistable_region")
    s |= {"wall_time_s": time.perf_counter() - start}
    report(s, outputs, "boundaries.json", args.json, _print_exact, s["wall_time_s"])
    missing = sum(f is None for c in ("xi_curve", "ratio_curve") if c in s
                  for f in s[c]["fold_vd"])
    if missing:
        raise RunsFailed(f"the grazing point was not found at {missing} points of the "
                         f"two-parameter curves (null in {outputs.path('boundaries.json')})")


#: The study of each --engine: the fold of limit cycles ends the smoothed model's
#: stick-slip cycle, the grazing point the exact model's.
_RUNS = {"smoothed": _run_smoothed, "exact": _run_exact}


def _curves(s: dict):
    """The two-parameter curves of a summary, as (the parameter's name, the curve)."""
    return [(name, s[key]) for key, name in (("xi_curve", "xi"), ("ratio_curve", "mu_st/mu_d"))
            if key in s]


def _print_exact(s: dict) -> None:
    print("single oscillator, exact switch model:")
    print(f"  Hopf     v_d = {s['hopf_vd']:.10f}")
    print(f"  grazing  v_d = {s['fold_vd']:.10f}  (slip arc {s['grazing_arc_time']:.6f}); "
          f"closed-form existence limit {s['existence_limit_nonsmooth']:.10f}, difference "
          f"{s['fold_minus_existence_limit']:+.1e}")
    for name, c in _curves(s):
        print(f"  {name:>10}  Hopf v_d   grazing v_d   d/d{name}   grazing - limit")
        for v, h, f, d, e in zip(c[name], c["hopf_vd"], c["fold_vd"], c["d_fold_vd"],
                                 c["fold_minus_existence_limit"]):
            if f is None:
                print(f"  {v:>10g}  {h:.6f}   not found")
            else:
                print(f"  {v:>10g}  {h:.6f}   {f:.8f}    {d:+.5f}    {e:+.1e}")


def _print_summary(s: dict) -> None:
    d = s["design"]
    print(f"single oscillator, eps = {s['eps']:g}:")
    analytic = ("" if s["hopf_vd_analytic"] is None else
                f"(analytic eps -> 0: {s['hopf_vd_analytic']:.10f}; eps correction "
                f"{s['hopf_eps_correction']:.2e}); ")
    print(f"  Hopf   v_d = {s['hopf_vd']:.10f}  {analytic}"
          f"Re(lambda) crosses with slope {s['hopf_growth_slope']:.4f}, omega "
          f"{s['hopf_omega']:.4f}")
    kind = "subcritical" if s["subcritical"] else "supercritical"
    print(f"         first Lyapunov coefficient {s['lyapunov_coefficient']:.4f}: {kind}")
    print(f"  fold   v_d = {s['fold_vd']:.6f}  (Floquet multipliers "
          f"{s['fold_multipliers'][0]:.6f}, {s['fold_multipliers'][1]:.6f}); non-smooth "
          f"existence limit {s['existence_limit_nonsmooth']:.6f}, difference "
          f"{s['fold_minus_existence_limit']:+.4f}")
    ratio = ("" if "ratio_curve" not in s else
             f"; d/d(mu_st/mu_d): {s['d_hopf_vd_d_ratio']:.4f}, {s['d_fold_vd_d_ratio']:.4f}")
    print(f"  d v_d,H/d xi = {s['d_hopf_vd_d_xi']:.4f}, d v_d,fold/d xi = "
          f"{s['d_fold_vd_d_xi']:.4f}{ratio}")
    for name, c in _curves(s):
        print(f"  {name:>10}  Hopf v_d   fold v_d   non-smooth limit   fold - limit")
        for v, h, f, e in zip(c[name], c["hopf_vd"], c["fold_vd"],
                              c["existence_limit_nonsmooth"]):
            fold = "not found" if f is None else f"{f:.6f}"
            diff = "" if f is None else f"{f - e:+.4f}"
            print(f"  {v:>10g}  {h:.6f}   {fold:>9}  {e:.6f}           {diff}")
    print(f"  design: window < {d['target_window']:g} for xi >= {d['xi']:.6f} "
          f"({d['optax_iterations']} optax iterations); simulation check "
          f"{'holds' if d['simulation_check']['holds'] else 'FAILS'}")
    if "ring" in s:
        r = s["ring"]
        print(f"chain of {r['n_osc']} ({r['boundary']}): Hopf v_d = {r['hopf_vd']:.10f} "
              f"(spread over the modes {r['hopf_vd_spread_over_modes']:.1e})")
        for kind in ("in-phase", "anti-phase"):
            if kind in r:
                k = r[kind]
                fold = (f"{k['fold_vd']:.6f}" if k.get("fold_converged") else
                        f"~{k['max_vd_on_branch']:.4f} (largest v_d on the branch; "
                        f"fold {'passed' if k.get('fold_detected') else 'not reached'})")
                print(f"  {kind}: fold v_d = {fold}; at v_d = {k['at_vd']}: "
                      f"{'stable' if k['stable'] else 'unstable'} (|multipliers| "
                      f"{k['multipliers'][0]:.4f}, {k['multipliers'][1]:.4f})")
