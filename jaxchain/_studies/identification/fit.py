"""`identify`: the parameters of a chain and its friction law fitted to measured
records by least squares through the integration, with their uncertainty."""

from __future__ import annotations

import dataclasses
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ..._engine.compat import checks_as_nan
from ..._engine.checks import as_solver
from ..._engine.engines import AbstractEngine, Exact, Smoothed
from ..._engine.exact.options import NonsmoothOptions
from ..._engine.options import SimulationOptions
from ..._engine.solver.registry import DEFAULT_SOLVER
from ..._errors import ValidationError
from ..._physics.params import ChainParams, parameter_value, with_parameter
from .records import Record
from .starts import breakaway_start, local_slopes
from .unknowns import Unknowns, unknowns_of
from .windows import Windows, column_noise, cut, residuals, window_flow, with_offsets


#: The fit's smoothing and tolerances by default (`fit_engine`): eps = 1e-5 keeps the
#: smoothing's bias below 0.5 % (1e-3, the simulations' `DEFAULT_EPS`, biases xi and
#: v0 by about 3 %); rtol 1e-6, atol 1e-8, tighter than a simulation's, because the
#: fit needs accurate forward-mode sensitivities (exact only for the discrete
#: solution): at the simulations' rtol 3e-5 Levenberg-Marquardt stalls far from the
#: minimum on the test records.
FIT_EPS, FIT_RTOL, FIT_ATOL = 1e-5, 1e-6, 1e-8

#: The former settings of `IdentifyOptions` that the engine value holds now.
_MOVED = ("eps", "solver", "rtol", "atol", "controller", "max_steps")


def fit_engine(name: str = "smoothed", *, solver=DEFAULT_SOLVER, eps=FIT_EPS,
               rtol: float = FIT_RTOL, atol: float = FIT_ATOL,
               controller: str = SimulationOptions().controller,
               max_steps: int = SimulationOptions().max_steps,
               params: ChainParams | None = None) -> AbstractEngine:
    """The engine of a fit named `name`, at the fit's settings: what
    `IdentifyOptions(engine=name)` and `jaxchain identify --engine` fit.

    **Arguments:**

    - `name`: "smoothed" (`Smoothed`: eq. (5) with tanh(v_rel/eps), by diffrax with
        `solver` and the step-size `controller`) or "exact" (`Exact`: the stick/slip
        switch model, event by event, with its own Runge-Kutta pair,
        `NonsmoothOptions.solver`; `solver`, `controller` and `eps` do not apply).
    - `eps`: the smoothed model's smoothing velocity (> 0), dimensionless;
        `FIT_EPS` = 1e-5 by default.
    - `rtol`, `atol`, `max_steps`: the integration of each window
        (`AbstractEngine.flow`); `FIT_RTOL`, `FIT_ATOL` by default.
    - `params`: the chain, for `solver="auto"` (`as_solver`).

    **Returns:**

    An `AbstractEngine`.

    **Raises:**

    `ValidationError` for another name, or a setting the engine refuses.
    """
    makers = {
        "smoothed": lambda: Smoothed(
            as_solver(solver, params=params, eps=eps),
            SimulationOptions(rtol=rtol, atol=atol, controller=controller,
                              max_steps=max_steps), eps),
        "exact": lambda: Exact(NonsmoothOptions(rtol=rtol, atol=atol, max_steps=max_steps))}
    if name not in makers:
        raise ValidationError(f"IdentifyOptions.engine must be 'smoothed', 'exact' or an "
                              f"engine value (jaxchain.Smoothed, jaxchain.Exact), got "
                              f"{name!r}")
    return makers[name]()


class IdentifyOptions(eqx.Module):
    """How `identify` fits.

    **Arguments** (times dimensionless, eq. (4)):

    - `window`: the length of a multiple-shooting window. The default, 10, is
        about one stick-slip period at the paper's parameters: long enough that
        every window holds a stick phase and a slip arc (what determines mu(0),
        mu(v) and xi), short enough that the misfit stays smooth in the window's
        initial state (measured in `benchmarks/identification_windows.py` and on
        the documentation page "Identification").
    - `engine`: the fitted model, as an engine value holding everything that shapes
        the integration of a window (its solver, tolerances, step budget):
        `Smoothed` (eq. (5) with tanh(v_rel/eps), by diffrax; the fit integrates the
        smoothed vector field at the engine's eps, an array leaf: a new eps does
        not recompile, and derivatives with respect to it flow through the fit) or
        `Exact` (the stick/slip switch model, event by event, its derivatives
        through every switch: no smoothing bias, at the cost of locating every
        event of every window). Or a name, "smoothed" (the default) or "exact",
        for that engine at the fit's settings (eps 1e-5, rtol 1e-6, atol 1e-8). Records of real stick-slip (or of the exact model) make eps a
        bias: 1e-5 keeps it below 0.5 % (1e-3, the simulations' default
        `DEFAULT_EPS`, biases xi and v0 by about 3 %). An engine value given
        without tolerances resolves them from its eps (`follow_eps`); the fit needs
        them tight (rtol <= 1e-6): at the simulations' rtol 3e-5
        Levenberg-Marquardt stalls far from the minimum on the test records.
    - `tol`: the Levenberg-Marquardt tolerance (optimistix, rtol = atol).
    - `max_iterations`: iteration budget of each stage.
    - `weights`: the weights of the continuity residuals in the successive stages:
        the first, 1, lets windows jump while the parameters settle (the point of
        multiple shooting); the last, 1e3, closes the jumps, so that the answer is
        that of the continuous trajectory.
    - `condition_limit`: the condition number of the parameters' correlation
        matrix above which the fit warns that a direction is poorly determined.

    **Raises:** `ValidationError` naming the field for a value that is not > 0, for
    an engine name other than "smoothed" and "exact", or for `eps`, `solver`,
    `rtol`, `atol`, `controller` or `max_steps` given here (the engine holds them);
    `TypeError` for an engine of another kind.
    """

    window: float = eqx.field(static=True)
    engine: AbstractEngine
    tol: float = eqx.field(static=True)
    max_iterations: int = eqx.field(static=True)
    weights: tuple = eqx.field(static=True)
    condition_limit: float = eqx.field(static=True)

    def __init__(self, window: float = 10.0, engine: AbstractEngine | str = "smoothed", *,
                 tol: float = 1e-6, max_iterations: int = 200, weights: tuple = (1.0, 1e3),
                 condition_limit: float = 1e6, **moved):
        unknown = sorted(set(moved) - set(_MOVED))
        if unknown:
            raise TypeError(f"IdentifyOptions got an unexpected keyword {unknown[0]!r}")
        if moved:
            names = ", ".join(sorted(moved))
            raise ValidationError(
                f"IdentifyOptions.{names}: the engine holds them now: give "
                "engine=jaxchain.Smoothed(solver, jaxchain.SimulationOptions(rtol=..., "
                "atol=...), eps=...) or jaxchain.Exact(jaxchain.NonsmoothOptions(...))")
        self.window = window
        self.engine = fit_engine(engine) if isinstance(engine, str) else engine
        self.tol = tol
        self.max_iterations = max_iterations
        self.weights = weights
        self.condition_limit = condition_limit

    def __check_init__(self):
        for name in ("window", "tol", "max_iterations", "condition_limit"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise ValidationError(f"IdentifyOptions.{name} must be a number > 0, got "
                                      f"{value!r}")
        if not isinstance(self.engine, AbstractEngine):
            raise TypeError(f"IdentifyOptions.engine must be 'smoothed', 'exact' or an "
                            f"engine value, got {type(self.engine).__name__}")
        if not self.weights or any(not w > 0 for w in self.weights):
            raise ValidationError(f"IdentifyOptions.weights must be numbers > 0, got "
                                  f"{self.weights!r}")


class _Problem(eqx.Module):
    """The least-squares problem: the unknowns u = (theta, the windows' initial
    states, the records' sensor offsets)."""

    base: ChainParams
    engine: AbstractEngine  # its array leaves (the smoothed engine's eps) are traced
    unknowns: Unknowns = eqx.field(static=True)
    windows: Windows
    offsets: bool = eqx.field(static=True)
    frozen: jnp.ndarray  # bool: the parameters held at their start (`held_out_rms`)

    def unpack(self, u):
        p = self.unknowns.size
        w, n = self.windows.n_windows, self.base.n_osc
        states = jnp.reshape(u[p:p + 2 * n * w], (w, 2, n))
        # the first record's sensor zero is the reference (offset 0), see `identify`
        offsets = jnp.concatenate([jnp.zeros(1), u[p + 2 * n * w:]]) if self.offsets \
            else None
        # frozen: no derivative, so that Levenberg-Marquardt leaves them where they
        # are; traced, so that a frozen fit runs the program of the free one
        theta = jnp.where(self.frozen, jax.lax.stop_gradient(u[:p]), u[:p])
        return theta, states, offsets

    def flow(self, theta, state, times, v_d):
        """One window: the states at `times` from `state`, at belt speed `v_d`."""
        params = with_parameter(self.unknowns.params(self.base, theta), "v_d", v_d)
        return _window_flow(params, state, times, self.engine)

    def predictions(self, u):
        """The model at every window's times, offsets included, shape (W, K + 1, 2,
        n_osc) (`with_offsets`)."""
        theta, states, offsets = self.unpack(u)
        return with_offsets(_flows(theta, states, self), self.windows, offsets)

    def parts(self, u, weighting):
        """(misfit, continuity) of `residuals`; `weighting` is (noise of each
        record's columns, shape (R, 2, n_osc); weight of the continuity)."""
        noise, weight = weighting
        return residuals(self.predictions(u), self.windows, self.unpack(u)[1], noise, weight)

    def residual(self, u, weighting):
        misfit, continuity = self.parts(u, weighting)
        return jnp.concatenate([jnp.ravel(misfit), jnp.ravel(continuity)])


#: Jitted, so that the integration is traced once (a jaxpr that vmap and the JVPs
#: transform) rather than at every trace of the residual by the least-squares solver.
_window_flow = checks_as_nan(eqx.filter_jit(window_flow))


@eqx.filter_custom_jvp
def _flows(theta, states, problem: _Problem):
    """Every window's states, shape (W, K + 1, 2, n_osc), with a JVP that uses the
    structure of multiple shooting: window w depends on theta and on its own state
    only, so its Jacobian has P + 2 n_osc columns, not those of every unknown. The
    Jacobians are computed once (forward mode, per window, vmapped) and every
    tangent is a product with them: a Levenberg-Marquardt Jacobian costs P + 2 n_osc
    tangent integrations per window instead of P + 2 n_osc W."""
    return jax.vmap(problem.flow, in_axes=(None, 0, 0, 0))(
        theta, states, problem.windows.times, problem.windows.v_d)


@_flows.def_jvp
def _flows_jvp(primals, tangents):
    theta, states, problem = primals
    t_theta, t_states, _ = tangents

    def one(th, state, times, v_d):
        ys = problem.flow(th, state, times, v_d)
        return ys, ys

    jac = jax.vmap(jax.jacfwd(one, argnums=(0, 1), has_aux=True), in_axes=(None, 0, 0, 0))
    (j_theta, j_state), ys = jac(theta, states, problem.windows.times, problem.windows.v_d)
    out = jnp.zeros_like(ys)
    if t_theta is not None:
        out = out + jnp.einsum("wkabp,p->wkab", j_theta, t_theta)
    if t_states is not None:
        out = out + jnp.einsum("wkabcd,wcd->wkab", j_state, t_states)
    return ys, out


class _Answer(eqx.Module):
    """A stage's answer and what the result needs at it."""

    u: jnp.ndarray
    ok: jnp.ndarray
    steps: jnp.ndarray
    misfit: jnp.ndarray  # weighted, flat
    j_data: jnp.ndarray
    j_cont: jnp.ndarray
    ys: jnp.ndarray  # `predictions`
    values: jnp.ndarray  # the fitted parameters' values
    g: jnp.ndarray  # d values / d theta


@checks_as_nan
@eqx.filter_jit
def _stage(problem: _Problem, u0, weighting, tol: float, max_iterations: int) -> _Answer:
    """One stage of the fit: Levenberg-Marquardt from `u0`, then, at its answer, the
    weighted misfit, the Jacobians of the misfit and of the unweighted jumps, the
    predictions and the parameters' values (one compiled program for the fit, its
    covariance and its figures)."""
    sol = optx.least_squares(lambda u, w: problem.residual(u, w),
                             optx.LevenbergMarquardt(rtol=tol, atol=tol), u0, weighting,
                             options=dict(jac="fwd"), max_steps=max_iterations, throw=False)

    def split(v):
        misfit, continuity = problem.parts(v, (weighting[0], 1.0))
        return jnp.ravel(misfit), jnp.ravel(continuity)

    u = sol.value
    j_data, j_cont = jax.jacfwd(split)(u)
    theta = problem.unpack(u)[0]

    def values(th):
        return problem.unknowns.values(problem.base, th) if problem.unknowns.size \
            else jnp.zeros(0)

    return _Answer(u=u, ok=sol.result == optx.RESULTS.successful,
                   steps=sol.stats["num_steps"], misfit=split(u)[0], j_data=j_data,
                   j_cont=j_cont,
                   ys=problem.predictions(u),
                   values=values(theta), g=jax.jacfwd(values)(theta))


@checks_as_nan
@eqx.filter_jit
def _value_and_jacobian(quantity, unknowns: Unknowns, base: ChainParams, theta):
    """quantity(params(theta)) and its Jacobian in theta, in one compiled program."""
    def q(th):
        value = jnp.asarray(quantity(unknowns.params(base, th)))
        return value, value

    g, value = jax.jacfwd(q, has_aux=True)(theta)
    return value, g


@dataclasses.dataclass(frozen=True)
class Identification:
    """The result of `identify`.

    **Fields:**

    - `chain`: the fitted chain (`ChainParams`: physics only, no smoothing).
    - `engine`: the fitted model, the engine value (`IdentifyOptions.engine`):
        `Smoothed` with its eps (the values are those of the smoothed model at
        that eps), or `Exact`.
    - `labels`: the fitted parameters (a vector parameter gets one label per
        entry), shape (P,).
    - `values`, `standard_errors`: their values and standard errors, shape (P,).
    - `covariance`, `correlation`: shape (P, P), from the Gauss-Newton covariance
        s^2 (J^T J)^-1 of the fit with continuity imposed, the residuals weighed
        by each column's noise and s^2 the variance factor (Bard, *Nonlinear
        Parameter Estimation* (1974), Ch. 7); the window states and offsets are
        marginalised out.
    - `offsets`, `offset_errors`: the sensor offsets, one per record, with
        their standard errors, shape (R,), relative to the first record's (0,
        standard error 0); None without `offsets=True`.
    - `sigma`: the residual standard deviation over all records (in their units).
    - `noise`: per record, the noise of each measured displacement column, shape
        (k,): the residual standard deviation by which the last stage weighs that
        column (the noise may differ between records and sensors).
    - `rss`, `n_data`, `n_free`: residual sum of squares (unweighted, in the
        records' units), measured values, free unknowns (parameters, first states
        of each record, offsets).
    - `aic`, `bic`: Akaike's and the Bayesian information criterion for Gaussian
        noise of unknown variance, n ln(rss/n) + 2k and n ln(rss/n) + k ln n.
    - `converged`: whether Levenberg-Marquardt met its tolerance in every stage.
    - `iterations`: its iterations over all stages.
    - `fits`: per record, the fitted model at the sample times, shape (m, k) for
        its k measured oscillators (offsets included).
    - `warnings`: what the fit warned about (ill-conditioning, no convergence).
    """

    chain: ChainParams
    engine: AbstractEngine
    labels: tuple
    values: np.ndarray
    standard_errors: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    offsets: np.ndarray | None
    offset_errors: np.ndarray | None
    sigma: float
    noise: tuple
    rss: float
    n_data: int
    n_free: int
    aic: float
    bic: float
    converged: bool
    iterations: int
    fits: tuple
    warnings: tuple
    unknowns: Unknowns
    theta: np.ndarray
    theta_covariance: np.ndarray
    base: ChainParams

    def propagate(self, quantity) -> tuple[np.ndarray, np.ndarray]:
        """A derived quantity and its standard error by the delta method through
        JAX's derivatives: var q = g C g^T, g = dq/dtheta at the fit, C the
        covariance of the fitted unknowns (first order: good while the standard
        errors are small against the scale on which q bends).

        **Arguments:** `quantity`: a function of a `ChainParams` returning a scalar
        or an array, differentiable by `jax.jacfwd` (a Hopf point, an existence
        limit, mu on a grid of speeds). The chain holds no eps: a quantity of the
        smoothed model gives its eps itself (`engine.eps` of this result for the
        fitted model's).

        **Returns:** (value, standard error), arrays of the quantity's shape."""
        value, g = _value_and_jacobian(quantity, self.unknowns, self.base,
                                       jnp.asarray(self.theta))
        value = np.asarray(value)
        g = np.asarray(g).reshape(value.size, -1)
        var = np.einsum("ij,jk,ik->i", g, self.theta_covariance, g)
        return value, np.sqrt(np.maximum(var, 0.0)).reshape(value.shape)

    def to_dict(self) -> dict:
        """The result as plain numbers, for `--json`."""
        out = {"parameters": {label: {"value": float(v), "standard_error": float(s)}
                              for label, v, s in zip(self.labels, self.values,
                                                     self.standard_errors)},
               "correlation": self.correlation.tolist(), "engine": self.engine.name,
               "eps": self.engine.attributes().get("eps"),
               "sigma": self.sigma,
               "rss": self.rss, "n_data": self.n_data, "n_free": self.n_free,
               "aic": self.aic, "bic": self.bic, "converged": self.converged,
               "iterations": self.iterations, "warnings": list(self.warnings)}
        if self.offsets is not None:
            out["offsets"] = [{"value": float(v), "standard_error": float(s)}
                              for v, s in zip(self.offsets, self.offset_errors)]
        return out

    def summary(self) -> str:
        """The fitted model (engine, eps) and the fitted parameters with their
        standard errors, as a table."""
        lines = [f"fitted by {self.engine.describe()}",
                 f"{'parameter':<12}{'value':>14}{'std. error':>14}{'rel.':>9}"]
        for label, v, s in zip(self.labels, self.values, self.standard_errors):
            rel = f"{abs(s / v):8.2%}" if v else "       -"
            lines.append(f"{label:<12}{v:14.6g}{s:14.3g} {rel}")
        if self.offsets is not None:
            for r, (v, s) in enumerate(zip(self.offsets, self.offset_errors)):
                lines.append(f"{f'offset[{r}]':<12}{v:14.6g}{s:14.3g}")
        lines.append(f"residual sigma {self.sigma:.4g} over {self.n_data} values, "
                     f"{self.iterations} iterations" + ("" if self.converged else
                                                        ", NOT converged"))
        return "\n".join(lines + [f"warning: {w}" for w in self.warnings])


def identify(records: list[Record], chain: ChainParams, fit=("mu_st", "mu_d", "v0", "xi"),
             *, start: dict | None = None, offsets: bool = False,
             options: IdentifyOptions = IdentifyOptions()) -> Identification:
    """Fit the named parameters of `chain` and its friction law to measured records
    by least squares, with gradients from JAX through the integration.

    Each record is cut into windows of `options.window` (multiple shooting: Bock
    (1983); van Domselaar & Hemker (1975)); each window is integrated by the
    fitted model, `options.engine` (the smoothed model, eq. (5) with tanh(v_rel/eps)
    friction at the engine's eps, or the exact switch model) from its own fitted
    initial state,
    and the residuals are the model minus every
    measured value, plus the jumps between consecutive windows. Levenberg-Marquardt
    (`optimistix.LevenbergMarquardt`, Jacobians by forward-mode autodiff through
    diffrax) solves it in stages of growing continuity weight
    (`IdentifyOptions.weights`), so that the answer is a continuous trajectory
    per record. The parameters are fitted as the logarithm of the positive ones
    and the excess of the static coefficient over the dynamic one
    (`unknowns_of`): mu_st > mu_d > 0, v0 > 0, xi > 0 at every iterate.

    Starting values: the chain's own values, replaced by the breakaway estimate of
    mu(0) and xi from the records (`breakaway_start`) where those are fitted, and
    by `start` where given; the windows' states from the measured samples (the
    velocity by finite differences where not measured; an unmeasured oscillator
    starts as the mean of the measured ones).

    **Arguments:**

    - `records`: the records (`read_record`, `record_from_dataset`), one belt
        speed each.
    - `chain`: the chain and its friction law, with the values of the parameters
        that are not fitted.
    - `fit`: the names of the fitted parameters (`unknowns_of`).
    - `start`: starting values by name (floats, or arrays of the field's shape).
    - `offsets`: also fit one sensor offset per record (added to its measured
        displacements), relative to the first record's: an offset common to all
        records is the same as a shift of the friction coefficient (x + c obeys
        eq. (5) with F + c, and F = +mu while v_rel <= 0, as in stick-slip), so
        only the differences are identifiable.
    - `options`: `IdentifyOptions`.

    **Returns:**

    `Identification`: the fitted chain, the values with standard errors and
    correlations, the per-record fits, the information criteria.

    **Raises:**

    `ValidationError` for no record, a record that does not fit the chain
    (`Record.check`), a bad name in `fit` or `start`, or a window too short.
    """
    problem, u0 = _problem(records, chain, fit, start, offsets, options)
    return _solve(problem, u0, records, chain, options)


def held_out_rms(records: list[Record], fit: Identification, *, offsets: bool = False,
                 options: IdentifyOptions = IdentifyOptions()) -> float:
    """The root mean square residual of the fitted model on records it was not
    fitted to: only the windows' states (and offsets) are fitted, with the
    parameters of `fit` held, by the compiled program of a fit of the same shapes.

    **Raises:** as `identify`."""
    problem, u0 = _problem(records, fit.chain, fit.unknowns.names, None, offsets, options,
                           frozen=True)
    check = _solve(problem, u0, records, fit.chain, options)
    return float(np.sqrt(check.rss / check.n_data))


def _solve(problem: "_Problem", u0, records, chain, options) -> Identification:
    """The stages of the fit (`identify`) from `u0`, and the result."""
    u, converged, iterations = u0, True, 0
    noise = np.ones((len(records), 2, chain.n_osc))
    answer = None
    for weight in options.weights:
        if answer is not None:  # weigh each column by its noise, from the stage before
            scale = noise[np.asarray(problem.windows.record)][:, None]
            misfit = np.reshape(np.asarray(answer.misfit), problem.windows.mask.shape) * scale
            noise = column_noise(problem.windows, misfit, len(records))
        weighting = (jnp.asarray(noise), jnp.asarray(weight / noise.min()))
        answer = _stage(problem, u, weighting, options.tol, options.max_iterations)
        u = answer.u
        converged &= bool(answer.ok)
        iterations += int(answer.steps)
    return _result(problem, records, chain, answer, noise, converged, iterations, options)


def _problem(records, chain, fit, start, offsets, options, frozen: bool = False
             ) -> tuple[_Problem, jnp.ndarray]:
    if not records:
        raise ValidationError("identify needs at least one record")
    unknowns = unknowns_of(chain, fit) if fit else Unknowns(names=(), sizes=(), kinds=())
    for rec in records:
        rec.check(chain.n_osc, 0)
    windows = cut(records, chain.n_osc, options.window)
    n_unknowns = unknowns.size + 2 * chain.n_osc * len(records) + (len(records) - 1) * offsets
    total = sum(rec.n_samples for rec in records)
    if total < n_unknowns:
        raise ValidationError(f"{records[0].source}: {total} measured values for "
                              f"{n_unknowns} unknowns: a fit needs more samples")
    base = chain
    if not frozen:
        base = _start_chain(records, base, unknowns, start or {})
    problem = _Problem(base=base, engine=options.engine, unknowns=unknowns,
                       windows=windows, offsets=offsets, frozen=jnp.asarray(frozen))
    states = _start_states(records, windows, chain.n_osc)
    parts = [unknowns.theta(base), np.ravel(states)]
    if offsets:
        parts.append(np.zeros(len(records) - 1))
    return problem, jnp.asarray(np.concatenate(parts))


def _start_chain(records, chain: ChainParams, unknowns: Unknowns, start: dict) -> ChainParams:
    law = type(chain.friction)
    given = dict(start)
    for name in given:
        if name not in unknowns.names:
            raise ValidationError(f"start: {name!r} is not a fitted parameter "
                                  f"({', '.join(unknowns.names)})")
    pairs = law.ordered_pairs()
    estimate = breakaway_start(records, chain)
    if pairs and pairs[0][0] in unknowns.names and "static" in estimate:
        given.setdefault(pairs[0][0], estimate["static"])
    if "xi" in unknowns.names and "xi" in estimate:
        given.setdefault("xi", float(np.clip(estimate["xi"], 1e-3, 1.0)))
    for upper, lower in pairs:  # keep the order: a dynamic level below the static one
        if upper in given and lower not in start and np.any(
                np.asarray(parameter_value(chain, lower)) >= given[upper]):
            given[lower] = 0.5 * np.asarray(given[upper])
    params = chain
    for name in sorted(given, key=lambda n: n in dict(pairs)):
        params = with_parameter(params, name, given[name])
    return params


def _start_states(records, windows: Windows, n_osc: int) -> np.ndarray:
    states = np.zeros((windows.n_windows, 2, n_osc))
    for w, (r, i) in enumerate(windows.start):
        rec = records[r]
        v = rec.v[i] if rec.v is not None else local_slopes(rec.t, rec.x)[i]
        states[w, 0, :] = np.mean(rec.x[i])
        states[w, 1, :] = np.mean(v)
        cols = np.asarray(rec.oscillators) - 1
        states[w, 0, cols] = rec.x[i]
        states[w, 1, cols] = v
    return states


def _result(problem: _Problem, records, chain, answer: _Answer, noise, converged,
            iterations, options) -> Identification:
    u = np.asarray(answer.u)
    misfit, j_data, j_cont = (np.asarray(a) for a in (answer.misfit, answer.j_data,
                                                      answer.j_cont))
    windows = problem.windows
    mask = np.asarray(windows.mask)
    scale = np.broadcast_to(noise[np.asarray(windows.record)][:, None], mask.shape)[mask]
    mask = mask.reshape(-1)
    misfit, j_data = misfit[mask], j_data[mask]
    weighted = float(misfit @ misfit)
    rss = float(np.sum((misfit * scale) ** 2))  # in the records' units
    n_data = int(mask.sum())
    # Continuity imposed: the unknowns move in the null space Z of its Jacobian.
    _, sv, vt = np.linalg.svd(j_cont, full_matrices=True)
    rank = int(np.sum(sv > sv.max(initial=0.0) * 1e-10)) if sv.size else 0
    z = vt[rank:].T
    n_free = z.shape[1]
    s2 = weighted / max(n_data - n_free, 1)  # the variance factor: about 1
    reduced = z.T @ j_data.T @ j_data @ z
    cov_u = s2 * z @ np.linalg.pinv(reduced, rcond=1e-14, hermitian=True) @ z.T
    p = problem.unknowns.size
    theta = np.asarray(u[:p])
    cov_theta = cov_u[:p, :p]
    g = np.asarray(answer.g).reshape(p, p)
    cov = g @ cov_theta @ g.T
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    corr = cov / np.outer(se, se) if p else cov
    notes = []
    if not converged:
        notes.append("Levenberg-Marquardt did not meet its tolerance: the values are the "
                     "last iterate; try other starting values (--start) or windows")
    if p > 1:
        notes.extend(_conditioning(corr, problem.unknowns.labels, options.condition_limit))
    for note in notes:
        warnings.warn(note, stacklevel=3)
    fits = _stitch(records, problem.windows, np.asarray(answer.ys))
    values = np.asarray(answer.values)
    # NumPy from here: an eager JAX operation would compile a program of its own
    fitted = problem.unknowns.with_values(problem.base, values)
    log_term = n_data * np.log(max(rss, 1e-300) / n_data)
    off, off_se = None, None
    if problem.offsets:
        k = len(records) - 1
        off = np.concatenate([[0.0], np.asarray(u)[len(u) - k:]])
        off_se = np.concatenate([[0.0], np.sqrt(np.maximum(np.diag(cov_u)[cov_u.shape[0] - k:],
                                                           0.0))])
    return Identification(
        chain=fitted, engine=options.engine,
        labels=problem.unknowns.labels,
        values=values, standard_errors=se,
        covariance=cov, correlation=corr, offsets=off, offset_errors=off_se,
        sigma=float(np.sqrt(rss / max(n_data - n_free, 1))),
        noise=_record_noise(records, noise), rss=rss, n_data=n_data, n_free=n_free,
        aic=float(log_term + 2 * n_free), bic=float(log_term + n_free * np.log(n_data)),
        converged=converged, iterations=iterations, fits=fits, warnings=tuple(notes),
        unknowns=problem.unknowns, theta=theta, theta_covariance=cov_theta,
        base=problem.base)


def _conditioning(corr: np.ndarray, labels, limit: float) -> list[str]:
    """A warning naming the poorly determined direction when the correlation matrix
    is ill-conditioned: its eigenvector of the smallest eigenvalue."""
    if not np.all(np.isfinite(corr)):
        return ["the covariance is singular: a fitted parameter has no effect on the "
                "records (or the fit failed); fix it, or measure more"]
    values, vectors = np.linalg.eigh(corr)
    if values[0] > 0 and values[-1] / values[0] < limit:
        return []
    direction = vectors[:, 0]
    terms = sorted(zip(np.abs(direction), direction, labels), reverse=True)
    named = " ".join(f"{c:+.2f} {label}" for a, c, label in terms if a > 0.1)
    cond = values[-1] / values[0] if values[0] > 0 else np.inf
    return [f"ill-conditioned (condition number {cond:.3g} of the correlation matrix): "
            f"the records hardly determine the direction {named} (relative to the "
            "standard errors); fix one of them, or measure more (other belt speeds, "
            "velocities, more oscillators)"]


def _record_noise(records, noise: np.ndarray) -> tuple:
    """Each record's noise estimate per measured displacement column, shape (k,)."""
    return tuple(noise[r, 0, np.asarray(rec.oscillators) - 1]
                 for r, rec in enumerate(records))


def _stitch(records, windows: Windows, ys: np.ndarray) -> tuple:
    fits = [np.zeros_like(rec.x) for rec in records]
    starts = list(windows.start) + [(None, None)]
    for w, (r, i) in enumerate(windows.start):
        nxt = starts[w + 1]
        end = nxt[1] if nxt[0] == r else records[r].t.size
        cols = np.asarray(records[r].oscillators) - 1
        fits[r][i:end] = ys[w, :end - i, 0][:, cols]
    return tuple(fits)
