"""The edges of the bistable range of belt speeds: the Hopf point of steady sliding
and the fold of the stick-slip limit cycle, for one oscillator and for the ring,
their sensitivities, and one design question."""

import dataclasses

import jax.numpy as jnp
import numpy as np

from .._bifurcation.branches import follow_branch
from .._bifurcation.continuation import Branch, ContinuationOptions
from .._bifurcation.damping_design import DampingDesign, smallest_damping
from .._bifurcation.fold import FoldPoint, fold_point
from .._bifurcation.hopf import (HopfPoint, hopf_eps_correction, hopf_point, hopf_speed,
                                 hopf_vd_analytic)
from .._bifurcation.limit_cycles import hopf_cycle
from .._bifurcation.periodic_orbit import periodic_orbit
from .._bifurcation.lyapunov_coefficient import first_lyapunov_coefficient
from .._bifurcation.shooting import Shooting, unpack
from .._bifurcation.two_parameter import BoundaryCurves, boundary_curves
from .._physics.initial import GivenState
from .._bifurcation.existence import stick_slip_existence_limit
from .._engine.engines import Smoothed, as_engine
from .._bifurcation.orbit_method import AbstractOrbitMethod
from .grazing_range import grazing_range
from .._engine.options import SimulationOptions
from .._physics.forces import DEFAULT_EPS
from .._physics.friction import ExponentialDecay
from .._physics.params import (
    chain_or_default, ChainParams, is_homogeneous_ring, single_oscillator, with_parameter,
)
from .._physics.record import chain_record
from .._engine.simulate import simulate
from .._engine.solver.registry import DEFAULT_SOLVER
from .._checks import check_positive


@dataclasses.dataclass
class Boundaries:
    """What `boundaries` found; `summary` is JSON-ready."""

    summary: dict
    branch: Branch | None
    fold: FoldPoint | None
    hopf: HopfPoint | None
    curves_xi: BoundaryCurves
    curves_ratio: BoundaryCurves | None
    design: DampingDesign | None
    ring_branches: dict


def _multipliers(orbit) -> list[float]:
    """The two largest Floquet multipliers in modulus."""
    return [float(m) for m in np.sort(np.abs(np.asarray(orbit.multipliers)))[::-1][:2]]


#: The horizon of the design's check by simulation (`_design_check`).
DESIGN_CHECK_OPTIONS = SimulationOptions(t_end=4000.0, transient=3500.0)


def _design_check(params: ChainParams, design: DampingDesign, target: float,
                  engine: Smoothed, margin: float = 0.05) -> dict:
    """Direct simulation on both sides of the design: at v_d = v_d,H(xi) + target
    the stick-slip cycle must survive for xi = (1 - margin) xi* (window wider than
    the target) and die for (1 + margin) xi* (narrower). Starts far outside the
    cycle (x = 3 above steady sliding) and integrates 4000 time units
    (`DESIGN_CHECK_OPTIONS`) with the solver and eps of `engine`."""
    engine = Smoothed(engine.solver, DESIGN_CHECK_OPTIONS, engine.eps)
    out = {}
    for side, factor in (("below", 1 - margin), ("above", 1 + margin)):
        p = with_parameter(params, "xi", design.xi * factor)
        v = hopf_speed(p, engine) + target
        p = with_parameter(p, "v_d", v)
        obs = simulate(p, GivenState(jnp.array([[3.5], [0.0]])), engine=engine)
        out[side] = {"xi": design.xi * factor, "v_d": v,
                     "amplitude": float(obs.amplitudes[0]), "n_halc": int(obs.n_halc)}
    out["holds"] = out["below"]["n_halc"] == 1 and out["above"]["amplitude"] < 1e-3
    return out


def _stick_slip_cycle(single: ChainParams, branch: Branch, hopf_vd: float, fold_vd: float,
                      method: Shooting):
    """The single oscillator's stable cycle inside its bistable window, at v_d = 1.5
    (the paper's scene) when the window holds it, else at the window's middle:
    shooting from the stable point of the continued branch nearest to that v_d."""
    v_d = 1.5 if hopf_vd < 1.5 < fold_vd else 0.5 * (hopf_vd + fold_vd)
    p = np.asarray(branch.p)[np.asarray(branch.converged)]
    stable = np.flatnonzero(np.asarray(branch.stable))
    if stable.size == 0:
        raise RuntimeError("no stable cycle on the single oscillator's branch to start the "
                           "chain's stick-slip states from")
    nearest = stable[np.argmin(np.abs(p[stable] - v_d))]
    y0, period = unpack(np.asarray(branch.u)[np.asarray(branch.converged)][nearest])
    return periodic_orbit(with_parameter(single, "v_d", v_d), (y0, float(period)), method)


def _ring_state(params: ChainParams, single, kind: str, method: Shooting, progress):
    """Continue the ring's fully stick-slipping state `kind` (in-phase or
    anti-phase: neighbours half a period apart) from the single oscillator's cycle
    at `single.params.v_d` towards its fold, by `method` (that of the cycle)."""
    n = params.n_osc
    if kind == "in-phase":
        y0 = jnp.tile(single.y0, (1, n))
    else:
        half = method.engine.flow(single.params, single.y0, single.period / 2)
        y0 = jnp.tile(jnp.concatenate([single.y0, half], axis=1), (1, n // 2))
    orbit = periodic_orbit(with_parameter(params, "v_d", single.params.v_d),
                           (y0, float(single.period)), method, throw=False)
    out = {"at_vd": float(single.params.v_d), "converged": bool(orbit.converged),
           "stable": bool(orbit.stable), "multipliers": _multipliers(orbit)}
    if not orbit.converged:
        return out, None
    followed = follow_branch(orbit, method, ContinuationOptions(
        ds=0.05, ds_max=0.1, p_max=2.5, max_points=60), directions=(1,), progress=progress)
    (problem, branch, _), *_ = followed.pieces
    out["branch_points"] = int(np.sum(np.asarray(branch.converged)))
    out["max_vd_on_branch"] = float(np.max(np.asarray(branch.p)[np.asarray(branch.converged)]))
    # Near the fold, every oscillator of the weakly coupled ring has a multiplier
    # near +1 (split by eta_c only), so the extended system may be too ill-posed to
    # converge; then the branch's largest belt speed brackets the fold to within
    # one continuation step.
    out |= {"fold_detected": bool(branch.folds), "fold_vd": None, "fold_converged": False}
    if branch.folds:
        fold = fold_point(problem, branch, throw=False)
        if bool(fold.converged):
            out |= {"fold_vd": float(fold.p), "fold_converged": True,
                    "fold_multipliers": _multipliers(fold.record)}
    return out, branch


def _curve_summary(single: ChainParams, where: str, curves: BoundaryCurves) -> dict:
    """A two-parameter curve as JSON-ready lists, with the non-smooth existence
    limit at each value beside the fold (an independent reference: the smoothed
    fold lies within about eps of it)."""
    values = np.asarray(curves.values)
    fold = [float(f) if ok else None
            for f, ok in zip(np.asarray(curves.fold_vd), np.asarray(curves.converged))]
    limit = [stick_slip_existence_limit(with_parameter(single, where, v)) for v in values]
    return {"hopf_vd": np.asarray(curves.hopf_vd).tolist(), "fold_vd": fold,
            "existence_limit_nonsmooth": limit,
            "fold_minus_existence_limit": [None if f is None else f - e
                                           for f, e in zip(fold, limit)],
            "d_hopf_vd": np.asarray(curves.d_hopf).tolist(),
            "d_fold_vd": [None if f is None else float(d)
                          for f, d in zip(fold, np.asarray(curves.d_fold))]}


#: The default grids of the two-parameter curves: xi, and mu_st/mu_d.
BISTABLE_XI_VALUES = (0.03, 0.04, 0.05, 0.06, 0.07, 0.08, 0.1)
BISTABLE_RATIO_VALUES = (1.6, 1.8, 2.0, 2.2, 2.4)


def bistable_range(params: ChainParams | None = None, *, target: float = 0.5,
                   xi_values=BISTABLE_XI_VALUES, ratio_values=BISTABLE_RATIO_VALUES,
                   ring: bool = True, method: AbstractOrbitMethod | None = None,
                   progress: bool = False) -> Boundaries:
    """The edges of the bistable range, where steady sliding and the stick-slip
    cycle coexist: the Hopf point of steady sliding below, and above it where the
    stick-slip cycle ends. On a model that smooths stick (`Smoothed`) the cycle
    ends at a fold of limit cycles, and the whole study runs:

    1. Single oscillator (the chain's first, `single_oscillator`, with its friction
       law): the Hopf point (Newton on the growth rate), its first Lyapunov
       coefficient, the limit-cycle branch from the Hopf point by shooting and
       pseudo-arclength continuation, the fold by its extended system, and the
       non-smooth existence limit to compare.
    2. The fold and Hopf belt speeds against xi, and for eq. (1) against
       mu_st/mu_d, with their derivatives by implicit differentiation.
    3. The design: the smallest xi whose bistable window is narrower than
       `target`, by optax, checked by simulation on both sides.
    4. The chain (`params`): the Hopf point of every Fourier mode on the
       homogeneous ring (of the leading eigenvalue on any other chain), and on the
       homogeneous ring of even N the folds of the fully stick-slipping in-phase
       and anti-phase states. `summary["chain"]` records the chain.

    **Arguments:**

    - `params`: the chain parameters (eq. (7), eta_c, N).
    - `target`: the design's window width, > 0.
    - `xi_values`, `ratio_values`: grids of xi and of mu_st/mu_d.
    - `ring`: also analyse the ring.
    On the exact stick/slip model (its engine has exact stick phases) the cycle
    ends where its slip arc grazes the belt speed, a discontinuity-induced
    bifurcation, not a fold: the Hopf point in closed form and the grazing point by
    Newton's method on its defining condition, with both curves and the grazing
    point's derivatives (`grazing_range`); there is no design and no ring.

    **Arguments:**

    - `params`: the chain parameters (eq. (7), eta_c, N).
    - `target`: the design's window width, > 0.
    - `xi_values`, `ratio_values`: grids of xi and of mu_st/mu_d.
    - `ring`: also analyse the ring.
    - `method`: the orbit method, `Shooting()` by default (the smoothed model at
        eps = 1e-3). Its engine's eps (the smoothing velocity of tanh(v_rel/eps),
        > 0, dimensionless) is that of every Hopf point, shooting and fold; the
        design's check simulates its model with the default solver
        (`AbstractEngine.simulating`, over `DESIGN_CHECK_OPTIONS`).
        `Shooting(Exact().for_orbits())` takes the exact model's route.
    - `progress`: show tqdm bars.

    **Returns:**

    `Boundaries`; `summary` holds `hopf_vd`, `fold_vd` (the fold, or the grazing
    point with `boundary` "grazing"), `eps`, `subcritical` and the rest as plain
    numbers. On the exact model `branch`, `fold`, `hopf` and `design` are None.

    **Raises:**

    `ValidationError` for target <= 0 or a bad grid; `RuntimeError` if a
    computation fails.
    """
    params = chain_or_default(params)
    check_positive("target", target)
    method = Shooting() if method is None else method
    if method.engine.has_stick_phases:  # stick exact: the cycle ends by grazing
        summary, (curves_xi, curves_ratio) = grazing_range(params, xi_values=xi_values,
                                                           ratio_values=ratio_values)
        return Boundaries(summary=summary, branch=None,
                          fold=None, hopf=None, curves_xi=curves_xi,
                          curves_ratio=curves_ratio, design=None, ring_branches={})
    method.engine.as_smoothed("bistable_range")
    run = _run_bistable(params, target, xi_values, ratio_values, ring, method, progress)
    return _boundaries(params, target, run)


def _run_bistable(params: ChainParams, target: float, xi_values, ratio_values, ring: bool,
                  method: Shooting, progress: bool) -> dict:
    """The computations of `bistable_range` by name: the single oscillator's edges
    (`_run_single`), their curves and the design (`_run_curves`), and with `ring` the
    chain's (`_run_ring`)."""
    run = _run_single(params, method, progress) | {"engine": method.engine.simulating()}
    run |= _run_curves(run, target, xi_values, ratio_values, progress)
    run["ring"], run["ring_branches"] = (_run_ring(params, run, progress) if ring
                                         else (None, {}))
    return run


def _run_single(params: ChainParams, method: Shooting, progress: bool) -> dict:
    """The single oscillator's Hopf point, its first Lyapunov coefficient, the
    limit-cycle branch from it (all of `method`'s model, smoothed at its eps), the
    branch's fold and the non-smooth existence limit."""
    eps = method.engine.as_smoothed("bistable_range").eps
    single = single_oscillator(params)
    hopf = hopf_point(single, engine=Smoothed(eps=eps))
    l1 = float(first_lyapunov_coefficient(with_parameter(single, "v_d", hopf.v_d[0]),
                                          engine=Smoothed(eps=eps)))
    start = hopf_cycle(single, method=method)
    followed = follow_branch(start, method, ContinuationOptions(
        ds=0.01, ds_max=0.1, p_min=0.5, p_max=2.5, max_points=90), directions=(1,),
        progress=progress)
    (problem, branch, _), *_ = followed.pieces
    fold = fold_point(problem, branch)
    return {"method": method, "eps": eps, "single": single, "hopf": hopf, "l1": l1,
            "problem": problem,
            "branch": branch, "fold": fold, "limit": stick_slip_existence_limit(single),
            "exponential": isinstance(single.friction, ExponentialDecay)}


def _run_curves(run: dict, target: float, xi_values, ratio_values, progress: bool) -> dict:
    """The fold and Hopf curves against xi and (for eq. (1)) mu_st, the smallest
    damping of window `target` and its check by simulation, and the closed-form
    Hopf point and its eps correction where they hold."""
    single, fold = run["single"], run["fold"]
    solution = jnp.concatenate([fold.u, fold.p[None], fold.null_vector])
    fold_problem = run["problem"].with_params(fold.record.params)
    out = {"curves_xi": boundary_curves(fold_problem, solution, "xi", xi_values,
                                        progress=progress), "curves_ratio": None}
    if run["exponential"]:
        mu_d = float(single.friction.mu_d)
        mu_values = mu_d * np.asarray(ratio_values)
        out["curves_ratio"] = boundary_curves(fold_problem, solution, "mu_st", mu_values,
                                              progress=progress)
        out |= {"mu_d": mu_d,
                "at_r": int(np.argmin(np.abs(mu_values - float(single.friction.mu_st))))}
    out["design"] = smallest_damping(fold_problem, solution, target)
    out["at"] = int(np.argmin(np.abs(np.asarray(out["curves_xi"].values) - float(single.xi))))
    exponential = run["exponential"]
    out |= {"hopf_vd_analytic": float(hopf_vd_analytic(single)) if exponential else None,
            "hopf_eps_correction": (float(hopf_eps_correction(single, run["engine"]))
                                    if exponential else None),
            "xi_curve": _curve_summary(single, "xi", out["curves_xi"]),
            "design_check": _design_check(single, out["design"], target, run["engine"])}
    if exponential:
        out["ratio_curve"] = _curve_summary(single, "mu_st", out["curves_ratio"])
    return out


def _run_ring(params: ChainParams, run: dict, progress: bool) -> tuple[dict, dict]:
    """The chain's Hopf point over its modes and, on the homogeneous ring of even N,
    the fully stick-slipping in-phase and anti-phase states (`_ring_state`)."""
    ring_hopf = hopf_point(params, engine=run["engine"])
    summary = {
        "n_osc": params.n_osc, "boundary": params.boundary,
        "hopf_vd": float(np.max(ring_hopf.v_d)),
        "hopf_vd_spread_over_modes": float(np.ptp(np.asarray(ring_hopf.v_d))),
        "hopf_omega_range": [float(np.min(ring_hopf.omega)), float(np.max(ring_hopf.omega))],
    }
    branches = {}
    if params.n_osc % 2 == 0 and is_homogeneous_ring(params):
        cycle = _stick_slip_cycle(run["single"], run["branch"], float(run["hopf"].v_d[0]),
                                  float(run["fold"].p), run["method"])
        for kind in ("in-phase", "anti-phase"):
            summary[kind], branches[kind] = _ring_state(params, cycle, kind, run["method"],
                                                        progress)
    return summary, branches


def _boundaries(params: ChainParams, target: float, run: dict) -> Boundaries:
    """The `Boundaries` of `bistable_range` and its JSON-ready summary, from the
    results of `_run_bistable`."""
    hopf, fold, branch, l1 = run["hopf"], run["fold"], run["branch"], run["l1"]
    curves_xi, design, at = run["curves_xi"], run["design"], run["at"]
    p_ok = np.asarray(branch.converged)
    summary = {
        "hopf_vd": float(hopf.v_d[0]),
        "fold_vd": float(fold.p),
        "eps": float(run["eps"]),
        "subcritical": l1 > 0 and float(branch.p[p_ok][1]) > float(hopf.v_d[0]),
        "hopf_vd_analytic": run["hopf_vd_analytic"],
        "hopf_eps_correction": run["hopf_eps_correction"],
        "hopf_newton_steps": int(hopf.newton_steps[0]),
        "hopf_omega": float(hopf.omega[0]),
        "hopf_growth_slope": float(hopf.slope[0]),
        "lyapunov_coefficient": l1,
        "existence_limit_nonsmooth": run["limit"],
        "fold_minus_existence_limit": float(fold.p) - run["limit"],
        "fold_multipliers": _multipliers(fold.record),
        "fold_amplitude": float(fold.record.amplitudes[0]),
        "fold_period": float(fold.record.period),
        "branch_points": int(p_ok.sum()), "branch_failed_points": int((~p_ok).sum()),
        "branch_stop": branch.stop.name,
        "d_hopf_vd_d_xi": float(curves_xi.d_hopf[at]),
        "d_fold_vd_d_xi": float(curves_xi.d_fold[at]),
        "xi_curve": {"xi": np.asarray(curves_xi.values).tolist(), **run["xi_curve"]},
        "design": {"target_window": target, "xi": design.xi, "window": design.window,
                   "hopf_vd": design.hopf_vd, "fold_vd": design.fold_vd,
                   "d_window_d_xi": design.d_window, "optax_iterations": len(design.history),
                   "converged": design.converged,
                   "simulation_check": run["design_check"]},
    }
    if run["exponential"]:
        mu_d, at_r, curves_ratio = run["mu_d"], run["at_r"], run["curves_ratio"]
        summary |= {
            "d_hopf_vd_d_ratio": float(mu_d * curves_ratio.d_hopf[at_r]),
            "d_fold_vd_d_ratio": float(mu_d * curves_ratio.d_fold[at_r]),
            "ratio_curve": {"mu_st/mu_d": (np.asarray(curves_ratio.values) / mu_d).tolist(),
                            **run["ratio_curve"]}}
    summary["chain"] = chain_record(params)
    if run["ring"] is not None:
        summary["ring"] = run["ring"]
    return Boundaries(summary=summary, branch=branch, fold=fold, hopf=hopf,
                      curves_xi=curves_xi, curves_ratio=run["curves_ratio"], design=design,
                      ring_branches=run["ring_branches"])


#: The horizon of the simulation dots of Fig. 3(a).
FIG3A_OPTIONS = SimulationOptions(t_end=3000.0, transient=2500.0)


def fig3a_simulations(params: ChainParams, v_d=np.round(np.arange(0.6, 2.21, 0.1), 2),
                      solver=DEFAULT_SOLVER, options: SimulationOptions = FIG3A_OPTIONS,
                      progress: bool = False, *, eps=DEFAULT_EPS):
    """The simulation dots of Fig. 3(a): the single oscillator at each belt speed
    from a small and a large initial displacement (x = 0.6 and 3.5, x' = 0),
    integrated by the smoothed engine at `eps` (the smoothing velocity of
    tanh(v_rel/eps), > 0, dimensionless; `DEFAULT_EPS` by default) with `solver`
    over `options` (t_end = 3000, observed after 2500, by default). Returns (v_d,
    energy) with energy of shape (n_vd, 2).

    **Raises:** `ValidationError` for eps <= 0, and as `ensemble`."""
    from .._sweeps.ensemble import ensemble

    single = single_oscillator(params)
    engine = as_engine("smoothed", solver, options, single, eps=eps)
    ds = ensemble(single, jnp.asarray(v_d), GivenState(jnp.array([[[0.6], [0.0]],
                                                                  [[3.5], [0.0]]])),
                  engine=engine, progress=progress)
    return np.asarray(v_d), ds["energy"].values
