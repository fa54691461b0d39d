"""The physics checks of a stress case: the energy balance along the trajectory, and
the known limits (steady sliding at large v_d, the decay rate of the linearised
ring, the Hopf point), each against an independent reference."""

import dataclasses

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._bifurcation.hopf import growth_rates
from ..._engine.engines import AbstractEngine, Smoothed, as_engine
from ..._physics.forces import DEFAULT_EPS, friction_coefficient
from ..._physics.friction import Coulomb, ExponentialDecay
from ..._physics.model import Model, mechanical_energy, split_vector_field, steady_sliding
from ..._physics.params import single_oscillator
from ..._bifurcation.existence import stick_slip_existence_limit
from ..._engine.observers.base import AbstractObserver
from ..._engine.smoothed import SPLIT_SOLVERS, integrate
from ..._engine.status import Status

#: Largest |E(t_end) - E(0) - W| allowed, relative to the energy that went through
#: the ring (E(0) + E(t_end) + the integral of |power|): 100 rtol. The local error
#: per step is below rtol, and the energy is a sum of squares of the state.
BALANCE_RTOLS = 100.0

#: Largest |measured - linear| decay rate of the deviation from steady sliding
#: allowed: a fixed part for the fit over a finite window (the energy of a mode
#: ripples at twice its frequency by 2 xi / omega), and a relative part.
RATE_ATOL, RATE_RTOL = 2e-3, 0.05

#: A Hopf check applies when the linear growth rate of steady sliding is within
#: HOPF_RATE of zero. It starts NUDGE from steady sliding, or twice the `_resolution`
#: of the tolerances where that is larger (the growth rate is fitted only where the
#: deviation is resolved), and small enough to stay linear.
HOPF_RATE, NUDGE = 1e-3, 1e-3


def _power_rows(y, elastic, friction, params):
    """The work rows of the balance state: the power of friction and damping on each
    oscillator, v (F - 2 xi v), and its absolute value |v F| + 2 xi v^2."""
    v, force = y[1], friction[1]
    damping = 2 * params.xi * v**2
    return v * force - damping, jnp.abs(v * force) + damping


def _balance_parts(t, z, model: Model):
    elastic, friction = split_vector_field(t, z[:2], model.params, model.eps)
    work, magnitude = _power_rows(z[:2], elastic, friction, model.params)
    zero = jnp.zeros_like(work)
    return (jnp.concatenate([elastic, jnp.stack([work, magnitude])]),
            jnp.concatenate([friction, jnp.stack([zero, zero])]))


def _balance_elastic(t, z, model):
    return _balance_parts(t, z, model)[0]


def _balance_friction(t, z, model):
    return _balance_parts(t, z, model)[1]


def _balance_field(t, z, model):
    return sum(_balance_parts(t, z, model))


def _balance_terms(solver: diffrax.AbstractSolver):
    """The terms of eq. (5) with the work integrals added: a state of shape
    (4, n_osc), rows x, x', W (the work done by friction and damping on each
    oscillator) and the integral of its absolute power, with the friction smoothed
    at the eps of their args (a `Model`). The work rows go to the non-stiff term of
    a split solver: they feed nothing back. Module-level functions, so that a
    second case with the same solver reuses the compiled run."""
    if isinstance(solver, SPLIT_SOLVERS):
        return diffrax.MultiTerm(diffrax.ODETerm(_balance_elastic),
                                 diffrax.ODETerm(_balance_friction))
    return diffrax.ODETerm(_balance_field)


def _resolution(params, eps, options) -> jnp.ndarray:
    """The smallest deviation from steady sliding (smoothed at `eps`) that the error
    control resolves: 100 times its tolerance rtol |y_ss| + atol at steady sliding
    (max over the components)."""
    scale = jnp.max(jnp.abs(steady_sliding(params, eps)))
    return 100.0 * (jnp.max(jnp.asarray(options.rtol)) * scale + jnp.max(jnp.asarray(options.atol)))


def _friction_derivatives(params) -> tuple[jnp.ndarray, jnp.ndarray]:
    """|d mu / d v_rel| and |d^2 mu / d v_rel^2| at v_rel = v_d, eq. (1), by JAX."""
    mu = lambda v: friction_coefficient(params, v)  # noqa: E731
    v_d = jnp.asarray(params.v_d, float)
    return jnp.abs(jax.grad(mu)(v_d)), jnp.abs(jax.grad(jax.grad(mu))(v_d))


def _linear_regime(params) -> jnp.ndarray:
    """The largest deviation a from steady sliding that is still linear: the friction
    law (eq. (1)) departs from its tangent at v_d by at most |mu''| a^2 / 2, kept
    below 1 % of the linear damping (2 xi + |mu'|) a; and a <= v_d / 10, far from
    stick."""
    slope, curvature = _friction_derivatives(params)
    return jnp.minimum(0.1 * params.v_d, 0.02 * (2 * params.xi + slope) / curvature)


class SlidingDeviation(AbstractObserver):
    """The deviation from steady sliding (the fixed point of the smoothed model at
    the eps of `args`, a `Model`) over the sampled window: its size a(t) =
    max_n |y_n - y_ss,n| over x and x', and the least-squares slope of log D
    against t, D the mechanical energy (`mechanical_energy`) of y - y_ss, over the
    samples where the deviation is resolved by the error control and linear
    (`_resolution` < a < `_linear_regime`). Half that slope is the decay (or growth)
    rate of the ring near steady sliding. Memory: 7 numbers."""

    def init(self, y0, args, options):
        zero = jnp.zeros(())
        return (zero, zero, zero, zero, zero, jnp.array(jnp.nan), jnp.array(jnp.nan))

    def update(self, state, chunk, args, options):
        if chunk.ts is None:
            return state
        n, st, sl, stt, stl, first, _ = state
        params = args.params
        dev = chunk.ys[:, :2] - steady_sliding(params, args.eps)[None]
        d = jax.vmap(lambda y: mechanical_energy(params, y))(dev)
        a = jnp.max(jnp.abs(dev), axis=(1, 2))
        used = ((a > _resolution(params, args.eps, options)) & (a < _linear_regime(params))
                & jnp.isfinite(d) & (d > 0))
        log_d = jnp.log(jnp.where(used, d, 1.0))
        t = jnp.where(used, chunk.ts, 0.0)
        first = jnp.where(jnp.isnan(first), a[0], first)
        return (n + used.sum(), st + t.sum(), sl + log_d.sum(), stt + (t * t).sum(),
                stl + (t * log_d).sum(), first, a[-1])

    def result(self, state, args, options):
        n, st, sl, stt, stl, first, last = state
        slope = (n * stl - st * sl) / (n * stt - st**2)
        return {"decay_rate": jnp.where(n > 10, slope / 2, jnp.nan),
                "rate_samples": n, "deviation_start": first, "deviation_end": last}

    def dims(self, options):
        return {"decay_rate": (), "rate_samples": (), "deviation_start": (),
                "deviation_end": ()}


_integrate = eqx.filter_jit(integrate)


def _smoothed(engine: AbstractEngine | str, what: str) -> Smoothed:
    """The smoothed engine that `engine` names (`as_engine`).

    **Raises:**

    `ValidationError` for the exact engine, in one line naming `what`.
    """
    return as_engine(engine).as_smoothed(what)


def balance_run(params, y0, engine: AbstractEngine | str = "smoothed") -> dict:
    """Integrate the case with its work integrals (`_balance_terms`) and observe its
    deviation from steady sliding (`SlidingDeviation`), with the engine of the run
    under test: its solver, options and eps.

    **Arguments:**

    - `params`: the chain.
    - `y0`: the initial state, shape (2, n_osc), dimensionless.
    - `engine`: the smoothed engine of the run ("smoothed", the defaults, or a
        `Smoothed` value holding its solver, options and eps).

    **Returns:**

    dict of `residual` (the relative energy-balance error), `energy_start`,
    `energy_end`, `work`, `decay_rate`, `rate_samples`, `deviation_start`,
    `deviation_end` (of `SlidingDeviation`, sampled from t = 0) and `status`
    (`Status`).

    **Raises:**

    `ValidationError` for the exact engine (the balance is that of the smoothed
    model) or an unknown engine name.
    """
    engine = _smoothed(engine, "the energy balance")
    solver = engine.solver
    z0 = jnp.concatenate([y0, jnp.zeros_like(y0)])
    from_start = dataclasses.replace(engine.options, transient=0.0)  # same steps, sampled
    (dev,), z, _, status = _integrate(_balance_terms(solver), solver, z0,
                                      Model(params, engine.eps), from_start,
                                      (SlidingDeviation(),))
    e0, e1 = mechanical_energy(params, y0), mechanical_energy(params, z[:2])
    work, through = jnp.sum(z[2]), jnp.sum(z[3])
    residual = jnp.abs(e1 - e0 - work) / (e0 + e1 + through)
    out = {"residual": residual, "energy_start": e0, "energy_end": e1, "work": work,
           "status": status, **dev}
    return {k: np.asarray(v).item() for k, v in out.items()}


def linear_rate(params, eps=DEFAULT_EPS) -> float:
    """The growth rate of steady sliding of the model smoothed at `eps` (> 0, shape
    (), dimensionless; `DEFAULT_EPS` by default): the largest max Re(lambda) over
    the ring's Fourier modes (`growth_rates`)."""
    return float(jnp.max(growth_rates(params, engine=Smoothed(eps=eps))))


def _sliding_expected(params, eps) -> str:
    """Why every trajectory must end at steady sliding, or "" when none of the known
    reasons holds: friction that does not weaken with speed (mu_st = mu_d: no
    negative damping feeds a vibration), or a belt faster than the single
    oscillator's stick-slip cycle can exist at (`stick_slip_existence_limit`) with
    weak coupling (eta_c <= 0.01), at which steady sliding is also linearly
    stable."""
    law = params.friction
    if isinstance(law, ExponentialDecay) and float(law.mu_st) == float(law.mu_d):
        return "mu_st = mu_d"
    if isinstance(law, Coulomb):
        return "Coulomb friction"
    if float(np.max(params.eta_c)) > 0.01 or linear_rate(params, eps) >= 0:
        return ""
    try:
        limit = stick_slip_existence_limit(single_oscillator(params))
    except ValueError:  # no Hopf point to bracket the limit from: claim nothing
        return ""
    if float(params.v_d) > 1.02 * limit:
        return f"v_d > the stick-slip existence limit {limit:.4f}"
    return ""


def _friction_slope(params) -> float:
    """|d mu / d v_rel| at steady sliding, eq. (1): (mu_st - mu_d)/v0 exp(-v_d/v0)."""
    return float(_friction_derivatives(params)[0])


def physics_checks(params, y0, engine: AbstractEngine | str, observed,
                   exactly_sliding: bool) -> list[tuple[bool, str]]:
    """Every physics check that applies to a finished run, each as (holds, what).

    **Arguments:**

    - `params`, `y0`: the run's.
    - `engine`: the run's smoothed engine (a `Smoothed` value: its solver, options
        and eps, the checks' steady sliding being that of the model at its eps).
    - `observed`: the run's `Observables`.
    - `exactly_sliding`: whether y0 is exactly steady sliding.

    **Returns:**

    A list of (bool, str): the energy balance always; the end at steady sliding
    when it is expected (`_sliding_expected`); the decay rate against the linear
    one (`linear_rate`, which is -xi when friction is constant) whenever the run
    ends at steady sliding; staying at steady sliding from it; the growth rate at
    the Hopf point, from a start `NUDGE` away from steady sliding.

    **Raises:**

    `ValidationError` for the exact engine.
    """
    engine = _smoothed(engine, "the physics checks")
    options, eps = engine.options, engine.eps
    balance = balance_run(params, y0, engine)
    if balance["status"] != Status.ok:
        return [(False, f"the energy-balance run failed with status {balance['status']}")]
    tol = BALANCE_RTOLS * float(np.max(np.asarray(options.rtol)))
    checks = [(balance["residual"] <= tol,
               f"energy balance |dE - W| = {balance['residual']:.1e} of the energy "
               f"through the ring (<= {tol:.0e})")]
    rate_ref = linear_rate(params, eps)
    constant = _friction_slope(params) < 1e-9
    reference = f"-xi = {-float(params.xi):.4g}" if constant else f"linear {rate_ref:.4g}"
    reason = _sliding_expected(params, eps)
    rate = balance["decay_rate"]
    if reason:
        checks.append((int(observed.n_halc) == 0
                       and balance["deviation_end"] < balance["deviation_start"]
                       and abs(rate - rate_ref) <= RATE_ATOL + RATE_RTOL * abs(rate_ref),
                       f"slides to steady sliding ({reason}): n_HALC = "
                       f"{int(observed.n_halc)}, decay rate {rate:.4g} (fit over "
                       f"{balance['rate_samples']} samples) vs {reference}"))
    if exactly_sliding:
        bound = float(_resolution(params, eps, options)) / 100 * np.exp(
            max(rate_ref, 0.0) * options.t_end)
        checks.append((balance["deviation_end"] <= bound,
                       f"stays at steady sliding: deviation {balance['deviation_end']:.1e}"
                       f" <= the tolerance {bound:.0e}"))
    if abs(rate_ref) < HOPF_RATE:
        size = max(NUDGE, 2 * float(_resolution(params, eps, options)))
        nudge = steady_sliding(params, eps).at[0].add(
            size * (-1.0) ** np.arange(1, params.n_osc + 1))
        near = balance_run(params, nudge, engine)
        checks.append((near["status"] == Status.ok and size < float(_linear_regime(params))
                       and abs(near["decay_rate"] - rate_ref) <= RATE_ATOL,
                       f"Hopf point: growth rate {near['decay_rate']:.2e} from steady "
                       f"sliding + {size:.1e} vs linear {rate_ref:.2e}"))
    return checks
