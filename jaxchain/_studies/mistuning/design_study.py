"""`design_study`: intentional mistuning by gradient, each way, against the
classical alternating (A-B) pattern and random draws of the same budget, with its
gradients checked by finite differences and its folds by direct simulation."""

import diffrax
import jax.numpy as jnp
import numpy as np

from ..._physics.chain import require_line
from ..._bifurcation.periodic_orbit import cycle_method, periodic_orbit
from ..._engine.engines import AbstractEngine, Smoothed, as_engine
from ..._engine.options import SimulationOptions
from ..._physics.params import chain_or_default, ChainParams, with_fields, with_parameter
from ..._engine.simulate import simulate
from .pattern_design import design_problems, intentional_mistuning, pattern_folds
from .edges import upper_edges
from ..._engine.status import Status

#: The simulations that check a fold, 5e-4 from it: tight tolerances, because the
#: basin of the stable cycle is thin there (the unstable cycle is near) and the
#: default tolerances' errors carry the state across it; long enough to pass the
#: slow passage past the ghost of the fold above it.
CHECK_OPTIONS = SimulationOptions(t_end=3000.0, transient=2500.0, rtol=1e-10, atol=1e-12)


def _exact(d: np.ndarray, budget: float) -> np.ndarray:
    """theta with pattern_deviations(theta, 2 budget, n, False) = d exactly."""
    return np.arctanh(np.asarray(d) / (2 * budget))


def _random_patterns(n_osc: int, budget: float, n: int, seed: int = 0) -> np.ndarray:
    """`n` random mistunings of the same budget: uniform on [-budget, budget], the
    mean removed and scaled back into the budget, shape (n, n_osc)."""
    d = np.random.default_rng(seed).uniform(-budget, budget, (n, n_osc))
    d -= d.mean(1, keepdims=True)
    return d * np.minimum(1.0, budget / np.abs(d).max(1, keepdims=True))


def _gradient_check(problem, solutions, theta, budget, zero_mean, seed=0, h=1e-3) -> dict:
    """The directional derivative of every site's fold along a random unit
    direction: implicit differentiation against central differences."""
    e = np.random.default_rng(seed).standard_normal(np.size(theta))
    e /= np.linalg.norm(e)
    folds, grads, sols, _ = pattern_folds(problem, solutions, theta, theta, budget, zero_mean)
    plus = pattern_folds(problem, sols, theta, theta + h * e, budget, zero_mean)[0]
    minus = pattern_folds(problem, sols, theta, theta - h * e, budget, zero_mean)[0]
    implicit, fd = grads @ e, (plus - minus) / (2 * h)
    return {"implicit": implicit.tolist(), "finite_difference": fd.tolist(),
            "largest_difference": float(np.abs(implicit - fd).max()),
            "largest_derivative": float(np.abs(implicit).max()), "h": h}


def _vibrates(obs, threshold: float = 0.1) -> bool:
    """Whether a run ended vibrating: some amplitude above `threshold` (steady
    sliding has none; near its fold the cycle's stick phase is too short for the
    HALC criterion, so n_HALC would not tell)."""
    return bool(int(obs.status) == Status.ok
                and float(np.max(np.asarray(obs.amplitudes))) > threshold)


def _fold_by_simulation(problem, solution, delta: np.ndarray, site: int, *,
                        offset: float = 5e-4,
                        options: SimulationOptions = CHECK_OPTIONS) -> dict:
    """Direct simulation on both sides of a fold of the single-site state, on the
    ring with deviations `delta` (the state at `site`, on the pattern rolled to the
    problem's site): at v_d = fold - offset from the stable cycle there (shooting
    from the fold's orbit moved along its null vector, the first converged cycle
    whose non-trivial Floquet multipliers lie inside the unit circle), which must
    persist; Tsit5 at rtol 1e-10 (`CHECK_OPTIONS`); at v_d = fold + offset from the
    fold's orbit, which must be lost (no cycle is left). Shooting and simulations
    of the problem's model (its method's engine).

    **Returns:**

    A dict: `fold`, `offset`, `persists_below` (None when no stable cycle was
    found below), `persists_above`, `agrees`.
    """
    n = problem.params.n_osc
    method = cycle_method(problem)
    centre = int(method.phase_oscillator)
    fold = float(solution[2 * n + 1])
    u, w = np.asarray(solution[: 2 * n + 1]), np.asarray(solution[2 * n + 2:])
    chain = _ring_like(problem.params, n, 1.0 + np.roll(np.asarray(delta), centre - site))
    below, above = (with_parameter(chain, "v_d", fold + s * offset) for s in (-1, 1))
    eps = method.engine.as_smoothed("the design's check by simulation").eps
    engine = Smoothed(diffrax.Tsit5(), options, eps)
    out = {"fold": fold, "offset": offset, "persists_below": None}
    for scale in (0.01, 0.03, 0.1):
        for sign in (1, -1):
            guess = u + sign * scale * w
            orbit = periodic_orbit(below, (guess[:-1].reshape(2, n), guess[-1]), method,
                                   throw=False)
            if bool(orbit.converged) and bool(orbit.stable):
                obs = simulate(below, orbit.y0, engine=engine)
                out["persists_below"] = _vibrates(obs)
                break
        if out["persists_below"] is not None:
            break
    obs = simulate(above, jnp.asarray(u[:-1].reshape(2, n)), engine=engine)
    out["persists_above"] = _vibrates(obs)
    out["agrees"] = bool(out["persists_below"]) and not out["persists_above"]
    return out


def _ring_like(params: ChainParams, n_osc: int, stiffness) -> ChainParams:
    """The ring of `params` (its damping, coupling, load and friction law), of
    `n_osc` oscillators with the given stiffness."""
    return with_fields(params, n_osc=n_osc, stiffness=stiffness, mistuning=None)


def design_study(params: ChainParams | None = None, *, budget: float = 0.05,
                 n_random: int = 8, steps: int = 15, chain_n_osc: int = 20,
                 engine: AbstractEngine = Smoothed(), progress: bool = True) -> dict:
    """Intentional mistuning by gradient (`intentional_mistuning`) on a ring of
    `params.n_osc` (one period of the pattern), against the alternating A-B
    pattern and `n_random` random draws of the same budget:

    - "lower" (zero mean), "retune" (lower, mean free) and "raise" (zero mean)
      designs, each with its highest single-site fold;
    - every fold by shooting, followed from the homogeneous ring (`pattern_folds`);
    - the gradient at each optimum against central finite differences;
    - each optimum's critical fold by direct simulation on both sides;
    - the patterns tiled on a ring of `chain_n_osc` and their upper edges by
      simulation (`upper_edges`), with random draws of that ring's length.

    Every fold, orbit and simulation is of the model of `engine`, a smoothed
    engine (`Smoothed()` by default: eq. (5) smoothed at eps = 1e-3; the upper
    edges are simulated by it, the folds' orbits by its flow made `for_orbits`).

    **Returns:**

    A dict of plain numbers and lists (JSON-ready), `eps` among them.

    **Raises:**

    As `intentional_mistuning`; `ValidationError` for an engine that does not
    smooth (the exact one: the folds are checked by simulations of the smoothed
    model).
    """
    params = chain_or_default(params, n_osc=4)
    require_line(params, "the mistuning design")
    engine = as_engine(engine).as_smoothed("the design study")
    n = params.n_osc
    start = design_problems(params, budget, engine=engine)
    problem, solutions, homogeneous = start
    out = {"budget": budget, "n_osc": n, "eps": float(engine.eps), "homogeneous_fold": homogeneous,
           "designs": {}}
    tiled = {"homogeneous": np.zeros(chain_n_osc)}
    for name, sense, zero_mean in (("lower", "lower", True), ("retune", "lower", False),
                                   ("raise", "raise", True)):
        d = intentional_mistuning(params, budget=budget, sense=sense, zero_mean=zero_mean,
                                  steps=steps, start=start, engine=engine, progress=progress)
        site = int(np.argmax(np.asarray(d.folds)))
        pattern = np.asarray(d.pattern)
        out["designs"][name] = {
            "pattern": pattern.tolist(), "folds": np.asarray(d.folds).tolist(),
            "edge": d.edge, "moved_by": d.edge - homogeneous,
            "history": np.asarray(d.history).tolist(),
            "gradient_check": _gradient_check(problem, list(d.solutions), d.theta, budget,
                                              zero_mean),
            "simulation": _fold_by_simulation(problem, d.solutions[site], pattern, site)}
        tiled[name] = np.tile(pattern, chain_n_osc // n)
    ab = budget * (-1.0) ** np.arange(n)
    theta_ab = _exact(ab, budget)
    folds, *_ = pattern_folds(problem, solutions, np.zeros(n), theta_ab, 2 * budget, False)
    out["ab"] = {"pattern": ab.tolist(), "folds": folds.tolist(), "edge": float(folds.max())}
    tiled["ab"] = np.tile(ab, chain_n_osc // n)
    draws = []
    for d in _random_patterns(n, budget, n_random):
        folds, _, _, ok = pattern_folds(problem, solutions, np.zeros(n), _exact(d, budget),
                                        2 * budget, False)
        draws.append({"pattern": d.tolist(), "folds": folds.tolist(),
                      "edge": float(folds.max()) if ok.all() else None})
    out["random"] = draws
    names = list(tiled) + [f"random {i}" for i in range(n_random)]
    patterns = list(tiled.values()) + list(_random_patterns(chain_n_osc, budget, n_random, 1))
    chains = [_ring_like(params, chain_n_osc, 1.0 + p) for p in patterns]
    edges = upper_edges(chains, engine=engine, steps=8, progress=progress)
    out["chain_edges"] = {"n_osc": chain_n_osc, "resolution": edges.attrs["resolution"],
                          "edge": {k: float(np.nanmax(e)) for k, e in
                                   zip(names, edges["edge"].values)}}
    return out
