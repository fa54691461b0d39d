"""The engine as a value: what integrates one trajectory of eq. (5), chosen where a
solver was chosen before. Two concrete engines behind one interface: `Smoothed`
(friction smoothed by tanh(v_rel/eps), integrated by diffrax) and `Exact` (the
stick/slip switch model of Leine et al. (1998), event by event). Every layer above
(`simulate`, `run_lanes`, `ensemble`) takes either without knowing which."""

import abc
import dataclasses
from typing import ClassVar

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .checks import as_solver, check_options
from .exact.options import REFERENCE_TOLERANCES, NonsmoothOptions
from .exact.phases import stick_phases
from .exact.solve import nonsmooth_flow, run_exact
from .exact.switching import initial_modes, mode_field
from .flow import smoothed_flow, smoothed_orbit_samples
from .horizon import AbstractHorizon
from .observables import Observables
from .options import SimulationOptions, check_stick_band, follow_eps
from .smoothed import run, run_observers
from .status import Status, failure_hint
from .solver.controller import step_size_controller
from .solver.registry import DEFAULT_SOLVER, SOLVERS
from .._physics.custom_types import State
from .._physics.forces import DEFAULT_EPS
from .._physics.friction import as_parameter, check_values
from .._physics.model import Model, jacobian, steady_sliding, vector_field
from .._physics.params import ChainParams
from .._physics.stick import min_slip_speed, sticks
from .._errors import ValidationError


class AbstractEngine(eqx.Module):
    """An engine: how one trajectory of eq. (5) is integrated and observed. It holds
    its own settings (solver, tolerances, horizon) and is passed as a value wherever
    a trajectory is run; `run` is pure and traceable, so that `run_lanes` can map it
    over lanes, on a queue of CPU devices or vmapped on a GPU.

    Subclasses: `Smoothed` and `Exact`. Name one by a string with its defaults
    (`as_engine`): `engine="smoothed"` (the default) or `engine="exact"`.
    """

    name: ClassVar[str]
    options: eqx.AbstractVar[AbstractHorizon]

    @abc.abstractmethod
    def run(self, params: ChainParams, y0: State, progress: bool = False) -> Observables:
        """One trajectory from the state `y0` (shape (2, n_osc)): its `Observables`
        over [transient, t_end]. Pure and traceable: no checks, no exceptions; a
        failure is its `status`. With `progress` (static), each chunk ticks the
        active progress bar."""

    @abc.abstractmethod
    def n_chunks(self) -> int:
        """The chunks of one run: the ticks of its progress bar."""

    def failure_hint(self, status: int, params: ChainParams) -> str:
        """What to do about a run that ended with `status` (`Status`)."""
        return Status(status).message

    @abc.abstractmethod
    def attributes(self) -> dict:
        """The engine and every setting that shapes its results, as dataset
        attributes and store keys (strings and numbers)."""

    # --- the flow map: what orbit methods integrate (`Shooting`) ---

    #: The flow's (rtol, atol) where an orbit method asks for accuracy
    #: (`for_orbits`): the trivial Floquet multiplier is 1 only as far as the flow
    #: is exact.
    orbit_tolerances: ClassVar[tuple[float, float]]

    #: The root finder that shooting starts from a simulated state with
    #: (`Shooting.root_finder`), where a study shoots from simulations.
    orbit_root_finder: ClassVar[str]

    @abc.abstractmethod
    def flow(self, params: ChainParams, y0: State, t) -> Array:
        """The state after time `t` from `y0` at t = 0: shape (2, n_osc) for `t` of
        shape (), or the states at each of the times `t` (increasing, >= 0), shape
        (m, 2, n_osc). Pure and traceable, differentiable in forward mode with
        respect to `params` and `y0` (`jax.jacfwd`: the monodromy matrix); NaN where
        the run failed. Integrated at the engine's own solver, step-size controller
        and tolerances."""

    @abc.abstractmethod
    def steady_sliding(self, params: ChainParams) -> State:
        """The fixed point of the engine's model, every oscillator sliding
        (`steady_sliding`), shape (2, n_osc)."""

    @abc.abstractmethod
    def field(self, params: ChainParams, y: State, t=0.0) -> State:
        """The vector field of the engine's model at the state `y` (shape (2, n_osc))
        and the time `t` (read only by a forcing, `ChainParams.forcing`): the flow's
        direction, that of the trivial Floquet multiplier of an autonomous chain."""

    def jacobian(self, params: ChainParams, y: State | None = None
                 ) -> Float[Array, "2n 2n"]:
        """The Jacobian of the flattened `field` at the state `y` (steady sliding,
        `steady_sliding`, if None), by `jax.jacfwd`: shape (2 n_osc, 2 n_osc),
        ordered (x_1..x_N, x_1'..x_N'). At steady sliding it is what the stability
        of steady sliding and its Hopf point are read from (`hopf_point`): the
        friction law's smoothing enters through the slope of the friction force
        there; on the exact engine (every oscillator slipping) that of the slip
        law, the limit eps -> 0 of the smoothed engine's."""
        y = self.steady_sliding(params) if y is None else jnp.asarray(y)
        return jax.jacfwd(lambda z: jnp.reshape(self.field(params, jnp.reshape(z, y.shape)),
                                                (-1,)))(jnp.reshape(y, (-1,)))

    @abc.abstractmethod
    def orbit_samples(self, params: ChainParams, y0: State, period, n_samples: int
                      ) -> tuple[Float[Array, "m 2 n"], Float[Array, ""]]:
        """`n_samples` states of the orbit through `y0` over one `period`, and the
        logarithm of its monodromy's determinant by Liouville's formula where the
        engine integrates it (NaN otherwise)."""

    @abc.abstractmethod
    def on_halc(self, params: ChainParams, ys: Float[Array, "m 2 n"]) -> Bool[Array, " n"]:
        """Whether each oscillator sticks at one of the states `ys` (the engine's
        stick: exact, or inside the smoothed stick band `sticks`)."""

    @abc.abstractmethod
    def simulating(self) -> "AbstractEngine":
        """The same model with the engine's default settings for simulations (its
        default solver and tolerances): what a study simulates with beside the
        orbits of an engine made `for_orbits`."""

    def with_horizon(self, horizon: AbstractHorizon) -> "AbstractEngine":
        """The engine with the horizon (t_end, transient, chunk_length) of
        `horizon`, its other settings kept."""
        options = dataclasses.replace(self.options, t_end=horizon.t_end,
                                      transient=horizon.transient,
                                      chunk_length=horizon.chunk_length)
        return eqx.tree_at(lambda e: e.options, self, options)

    #: Whether the engine smooths the friction law (and has an eps).
    smooths: ClassVar[bool] = False

    #: Whether the engine's orbits have exact stick phases (`stick_phases`).
    has_stick_phases: ClassVar[bool] = False

    def stick_phases(self, params: ChainParams, y0: State, period):
        """The stick phases of the orbit through `y0` (the exact engine's switch log).
        Raises `ValidationError` where the engine has none (it smooths stick)."""
        raise ValidationError(f"the {self.name} engine has no exact stick phases: its "
                              "friction law is smoothed; use the exact engine")

    def holding(self, oscillators: tuple[int, ...]) -> "AbstractEngine":
        """The engine with `oscillators` held in slip (`NonsmoothOptions.held`).
        Raises `ValidationError` where the engine has no modes to hold."""
        raise ValidationError(f"the {self.name} engine has no stick and slip modes to hold; "
                              "use the exact engine")

    @abc.abstractmethod
    def for_orbits(self, rtol: float | None = None, atol: float | None = None
                   ) -> "AbstractEngine":
        """The same model integrated as orbit methods need it: Tsit5 (explicit, fifth
        order: at shooting's tolerances an implicit method costs 20 times more per
        period, measured on the ring of 4) at `rtol`, `atol` (`orbit_tolerances` where
        None)."""

    def run_observers(self, params: ChainParams, y0: State, observers: tuple,
                      progress: bool = False) -> dict:
        """One trajectory with the given observers only (`observe`); the smoothed
        engine's. Raises `ValidationError` where the engine cannot."""
        raise ValidationError(f"the {self.name} engine observes amplitudes, energy and "
                              "the HALC only (Extrema): run other observers with "
                              "engine='smoothed'")

    # --- behaviour the studies ask of an engine ---

    @abc.abstractmethod
    def describe(self) -> str:
        """The model this engine integrates, in one line for a result's summary
        ("the smoothed model, eps = 1e-05")."""

    @abc.abstractmethod
    def can_observe(self, observers: tuple) -> bool:
        """Whether `run_observers` runs `observers` (the smoothed engine runs any);
        where not, the engine observes its `Observables` only."""

    @abc.abstractmethod
    def with_parameter(self, name: str, value) -> "AbstractEngine":
        """This engine with its parameter `name` (one of the engine's own, such as
        the smoothed engine's "eps") at `value`, every other setting kept, its
        resolved tolerances included (`eqx.tree_at`: a swept value does not
        recompile).

        **Raises:**

        `ValidationError` in one line where the engine has no such parameter.
        """

    @abc.abstractmethod
    def as_smoothed(self, what: str) -> "Smoothed":
        """This engine as the smoothed one, for `what`, which integrates the smoothed
        model with its solver, options and eps.

        **Raises:**

        `ValidationError` in one line naming `what` where the engine smooths
        nothing (the exact one).
        """


class Smoothed(AbstractEngine):
    """The smoothed engine: eq. (5) with the friction law's sign(v_rel) smoothed as
    tanh(v_rel/eps) (eq. (1) of the paper with eq. (7)), integrated by a diffrax
    solver in chunks with dense output observed as it goes (`simulate`). The
    smoothing is the engine's, not the chain's: `ChainParams` holds physics only.

    **Arguments:**

    - `solver`: a diffrax solver or the name of one (`SOLVERS`); `Ros34PW2()` by
        default (`DEFAULT_SOLVER`). "auto" (chosen from eps) is resolved by
        `as_engine`, which sees the chain.
    - `options`: `SimulationOptions` (horizon, tolerances, sampling). Tolerances
        left None follow eps (`follow_eps`: rtol = min(3e-5, eps/30), atol =
        min(3e-7, eps/3000)); the engine holds them resolved.
    - `eps`: the smoothing velocity of tanh(v_rel/eps) (> 0), shape (),
        dimensionless (a fraction of x_0 omega_n, eqs. (4)-(6)); `DEFAULT_EPS` =
        1e-3 by default. An array leaf: a new eps does not recompile, and
        derivatives with respect to it flow through a run.

    **Raises:**

    `ValidationError` for an unknown solver name, eps <= 0 (or not finite), or
    tolerances given that cannot resolve the stick band |v_rel| <= 3 eps
    (`check_stick_band`: rtol + atol > 100 eps); `TypeError` for options of
    another kind.
    """

    name: ClassVar[str] = "smoothed"
    smooths: ClassVar[bool] = True
    solver: diffrax.AbstractSolver
    options: SimulationOptions
    eps: ArrayLike = eqx.field(converter=as_parameter)

    def __init__(self, solver: diffrax.AbstractSolver | str = DEFAULT_SOLVER,
                 options: SimulationOptions = SimulationOptions(), eps=DEFAULT_EPS):
        self.solver = as_solver(solver)
        self.options = follow_eps(check_options(options), eps)
        self.eps = eps

    def __check_init__(self):
        check_values("Smoothed", {"eps": self.eps}, {"eps": (lambda a: a > 0, "> 0")})
        if np.ndim(self.eps) != 0:
            raise ValidationError(f"Smoothed.eps must be one number (shape ()), got shape "
                                  f"{np.shape(self.eps)}")
        check_stick_band(self.options, self.eps)

    def run(self, params: ChainParams, y0: State, progress: bool = False) -> Observables:
        return run(params, self.eps, y0, self.solver, self.options, progress)

    def run_observers(self, params: ChainParams, y0: State, observers: tuple,
                      progress: bool = False) -> dict:
        return run_observers(params, self.eps, y0, self.solver, self.options, observers,
                             progress)

    def n_chunks(self) -> int:
        return self.options.n_chunks()

    def failure_hint(self, status: int, params: ChainParams) -> str:
        return failure_hint(status, params, self.solver, self.options, self.eps)

    def attributes(self) -> dict:
        return {"engine": self.name, "eps": float(self.eps),
                "solver": type(self.solver).__name__,
                "rtol": self.options.rtol, "atol": self.options.atol}

    orbit_tolerances: ClassVar[tuple[float, float]] = (1e-10, 1e-12)
    # the smoothed flow's derivative is large across each stick-slip switch:
    # Levenberg-Marquardt converges from a simulated chain's rough state
    orbit_root_finder: ClassVar[str] = "levenberg-marquardt"

    def _flow(self, params, y0, t1, saveat):
        return smoothed_flow(Model(params, self.eps), self.solver,
                             step_size_controller(self.options), self.options.max_steps, y0,
                             t1, saveat)

    def flow(self, params: ChainParams, y0: State, t) -> Array:
        if np.ndim(t) == 0:
            return self._flow(params, y0, t, diffrax.SaveAt(t1=True))[-1]
        return self._flow(params, y0, t[-1], diffrax.SaveAt(ts=t))

    def field(self, params: ChainParams, y: State, t=0.0) -> State:
        return vector_field(t, y, params, self.eps)

    def steady_sliding(self, params: ChainParams) -> State:
        return steady_sliding(params, self.eps)

    def jacobian(self, params: ChainParams, y: State | None = None
                 ) -> Float[Array, "2n 2n"]:
        # one compiled program (`jaxchain._physics.model.jacobian`)
        return jacobian(params, y, self.eps)

    def simulating(self) -> "Smoothed":
        return Smoothed(eps=self.eps)

    def orbit_samples(self, params, y0, period, n_samples):
        # n_samples from 0 to the period, both ends included
        return smoothed_orbit_samples(Model(params, self.eps), self.solver,
                                      step_size_controller(self.options),
                                      self.options.max_steps, y0, period, n_samples)

    def on_halc(self, params, ys):
        return sticks(min_slip_speed(ys[:, 1], params.v_d), self.eps)

    def for_orbits(self, rtol=None, atol=None) -> "Smoothed":
        default_rtol, default_atol = self.orbit_tolerances
        # diffrax's PID controller: smooth in the start, as Newton's method wants
        return Smoothed(diffrax.Tsit5(), SimulationOptions(
            rtol=default_rtol if rtol is None else rtol,
            atol=default_atol if atol is None else atol, controller="diffrax"), self.eps)

    # --- behaviour the studies ask of an engine ---

    def describe(self) -> str:
        return f"the smoothed model, eps = {float(self.eps):g}"

    def can_observe(self, observers: tuple) -> bool:
        return True

    def with_parameter(self, name: str, value) -> "Smoothed":
        if name != "eps":
            raise ValidationError(f"{name}: the smoothed engine's only parameter is eps "
                                  "(the chain's are fields of ChainParams)")
        return eqx.tree_at(lambda e: e.eps, self, value)

    def as_smoothed(self, what: str) -> "Smoothed":
        return self


class Exact(AbstractEngine):
    """The exact engine: the stick/slip switch model of Leine et al. (1998),
    Nonlinear Dynamics 16, 41-54, without its stick band (stick is exact, x_n' =
    v_d): smooth slip segments integrated by diffrax, switches located as events
    (`jaxchain/_engine/exact/stepping.py`). No eps: nothing is smoothed. Its observables
    are those of the smoothed engine (`Observables`), in the same layout, with its own
    fields filled in (the switch log, the energy balance); an oscillator is on the
    HALC when it sticks during the window.

    **Arguments:**

    - `options`: `NonsmoothOptions` (horizon, tolerances, event budgets).

    **Raises:**

    `TypeError` for options of another kind.
    """

    name: ClassVar[str] = "exact"
    options: NonsmoothOptions = NonsmoothOptions()

    def __check_init__(self):
        if not isinstance(self.options, NonsmoothOptions):
            raise TypeError(f"Exact takes NonsmoothOptions, got "
                            f"{type(self.options).__name__}")

    def run(self, params: ChainParams, y0: State, progress: bool = False) -> Observables:
        return run_exact(_autonomous(params), y0, self.options, progress)

    def n_chunks(self) -> int:
        return self.options.n_chunks(halves=True)  # the window's halves are chunked apart

    def attributes(self) -> dict:
        return {"engine": self.name, "solver": self.options.solver,
                "rtol": self.options.rtol, "atol": self.options.atol,
                "root_tol": self.options.root_tol}

    orbit_tolerances: ClassVar[tuple[float, float]] = (REFERENCE_TOLERANCES["rtol"],
                                                       REFERENCE_TOLERANCES["atol"])
    # Newton's method through the saltation matrices, damped where it fails
    orbit_root_finder: ClassVar[str] = "newton"

    def flow(self, params: ChainParams, y0: State, t) -> Array:
        ys, status = nonsmooth_flow(_autonomous(params), y0, jnp.atleast_1d(t), self.options)
        ys = jnp.where(status == Status.ok, ys, jnp.nan)
        return ys[-1] if np.ndim(t) == 0 else ys

    def field(self, params: ChainParams, y: State, t=0.0) -> State:
        params = _autonomous(params)
        return mode_field(t, (y, None), (params, initial_modes(params, y)))[0]

    def steady_sliding(self, params: ChainParams) -> State:
        return steady_sliding(params)

    has_stick_phases: ClassVar[bool] = True

    def simulating(self) -> "Exact":
        return Exact()

    def stick_phases(self, params: ChainParams, y0: State, period):
        return stick_phases(_autonomous(params), y0, period, self.options)

    def holding(self, oscillators: tuple[int, ...]) -> "Exact":
        return Exact(dataclasses.replace(self.options, held=tuple(oscillators)))

    def orbit_samples(self, params, y0, period, n_samples):
        # n_samples after the start, the last at the period; no Liouville integral
        # (the saltation matrices' determinants are not integrated)
        ts = period * jnp.linspace(0.0, 1.0, n_samples + 1)[1:]
        return self.flow(params, y0, ts), jnp.asarray(jnp.nan)

    def on_halc(self, params, ys):
        return jnp.any(ys[:, 1] == params.v_d, axis=0)

    def for_orbits(self, rtol=None, atol=None) -> "Exact":
        default_rtol, default_atol = self.orbit_tolerances
        return Exact(dataclasses.replace(
            self.options, solver=REFERENCE_TOLERANCES["solver"], adjoint="forward",
            rtol=default_rtol if rtol is None else rtol,
            atol=default_atol if atol is None else atol, t_end=1.0, transient=0.0))

    # --- behaviour the studies ask of an engine ---

    def describe(self) -> str:
        return "the exact stick/slip model"

    def can_observe(self, observers: tuple) -> bool:
        return False

    def with_parameter(self, name: str, value) -> "Exact":
        raise ValidationError(f"{name}: the exact engine has no {name} (it does not smooth "
                              f"the friction law); give {name} to a jaxchain.Smoothed engine")

    def as_smoothed(self, what: str) -> "Smoothed":
        raise ValidationError(f"engine: {what} integrates the smoothed model; the "
                              f"{self.name} engine has no eps to smooth it with: give "
                              "engine='smoothed' or a jaxchain.Smoothed")


def _autonomous(params: ChainParams) -> ChainParams:
    """`params`, checked to carry no forcing: the exact engine's switch conditions
    (`jaxchain/_engine/exact/switching.py`) are those of the autonomous eq. (5).

    **Raises:** `ValidationError` for a forced chain."""
    if params.forcing is not None:
        raise ValidationError("forcing: the exact engine does not yet take a forced chain "
                              "(its stick/slip switches are those of the autonomous eq. (5)); "
                              "give a jaxchain.Smoothed engine")
    return params


#: The engines by name, each with its defaults.
ENGINES = {"smoothed": Smoothed, "exact": Exact}


def as_engine(engine: AbstractEngine | str = "smoothed",
              solver: diffrax.AbstractSolver | str | None = None,
              options: AbstractHorizon | None = None,
              params: ChainParams | None = None, eps=None) -> AbstractEngine:
    """The engine value that `engine` names, with `solver`, `options` and `eps`
    where given.

    **Arguments:**

    - `engine`: "smoothed", "exact" (`ENGINES`), or an engine value (returned as is;
        `solver` and `options` must then be None).
    - `solver`: the smoothed engine's solver (a diffrax solver, a name of `SOLVERS`,
        or "auto", chosen from eps by `auto_solver` with `params`).
    - `options`: `SimulationOptions` for the smoothed engine; for the exact one
        `NonsmoothOptions`, or `SimulationOptions` whose horizon (t_end, transient,
        chunk_length) it takes with its own tolerances.
    - `params`: the chain, for `solver="auto"`.
    - `eps`: the smoothed engine's smoothing velocity (`Smoothed.eps`);
        `DEFAULT_EPS` when None.

    **Returns:**

    An `AbstractEngine`.

    **Raises:**

    `ValidationError` for an unknown engine name, a solver or eps given to the exact
    engine, or settings given beside an engine value; `TypeError` for options of another kind.
    """
    if isinstance(engine, AbstractEngine):
        if solver is not None or options is not None or eps is not None:
            raise ValidationError("give the solver, options and eps inside the engine "
                                  "value, not beside it")
        return engine
    if engine in ("queue", "vmap"):
        raise ValidationError(f"engine={engine!r}: engine names the model now ('smoothed' or "
                              f"'exact'); how lanes are run is schedule={engine!r}")
    if engine not in ENGINES:
        raise ValidationError(f"engine must be one of {sorted(ENGINES)} or an engine value, "
                              f"got {engine!r}")
    if engine == "smoothed":
        eps = DEFAULT_EPS if eps is None else eps
        solver = SOLVERS[DEFAULT_SOLVER]() if solver is None else as_solver(
            solver, params=params, eps=eps)
        return Smoothed(solver, SimulationOptions() if options is None else options, eps)
    if eps is not None:
        raise ValidationError("eps: the exact engine has no eps (it does not smooth the "
                              "friction law); give eps to engine='smoothed'")
    if solver is not None:
        raise ValidationError("the exact engine takes no solver: it integrates its slip "
                              "segments itself (NonsmoothOptions sets its tolerances)")
    if isinstance(options, SimulationOptions):
        options = NonsmoothOptions(t_end=options.t_end, transient=options.transient,
                                   chunk_length=options.chunk_length)
    return Exact(NonsmoothOptions() if options is None else options)
