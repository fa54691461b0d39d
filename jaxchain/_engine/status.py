"""The one vocabulary of how a run ended: `Status`, an enumeration with a message
per member, in the style of diffrax's, lineax's and optimistix's `RESULTS`, and
beside it the hint for each failure (`failure_hint`). Statuses are stored as their
integer values (in the arrays of a run, under vmap, in zarr and netCDF files, with
CF flag attributes: `flag_attributes`)."""

import enum

import diffrax
import jax.numpy as jnp
import numpy as np

from .options import SimulationOptions, follow_eps
from .._physics.model import mechanical_energy
from .._physics.params import ChainParams
from .solver.registry import DEFAULT_SOLVER, SOLVERS, stick_stiffness


class Status(enum.IntEnum):
    """How a run ended. An `int` (an `enum.IntEnum`): a status lives in integer
    arrays (one per trajectory under `vmap`, in zarr stores and netCDF files), and a
    member compares with them inside and outside `jax.jit`
    (`status == Status.ok`). Each member carries its `message`.

    - For a trajectory of the smoothed engine (`simulate`, `ensemble`, `sweep`) and
        of the non-smooth reference (`Exact`): `ok`,
        `max_steps_reached`, `solver_failed`, `non_finite_state`,
        `step_size_collapsed`, and for the reference `event_not_resolved`; a cell of
        a sweep that has not run yet is `not_run`.
    - For a continuation (`Branch.stop`): `max_points_reached` and
        `left_parameter_range` end a branch as asked, `newton_failed` ends it early.

    `failure_hint` says what to do about a failed trajectory, for its parameters,
    solver and options.
    """

    message: str

    def __new__(cls, value: int, message: str):
        member = int.__new__(cls, value)
        member._value_ = value
        member.message = message
        return member

    not_run = -1, "not run yet (a sweep's cell whose batch has not finished)"
    ok = 0, "ok"
    max_steps_reached = 1, ("max_steps reached in one chunk: raise max_steps or use a "
                            "larger eps")
    solver_failed = 2, ("solver failed (for example a failed implicit solve): tighten "
                        "the tolerances, use another solver or a larger eps")
    non_finite_state = 3, ("non-finite state: the initial state or the trajectory is "
                           "not finite; check them")
    step_size_collapsed = 4, ("step size collapsed: max_steps spent on steps shorter "
                              "than options.dtmin on average; use a larger eps, looser "
                              "tolerances or another solver")
    event_not_resolved = 5, ("event not resolved: max_events reached in one chunk "
                             "(chattering), or an event located where no guard is "
                             "within switch_tol; raise max_events or switch_tol")
    max_points_reached = 6, "max_points reached"
    newton_failed = 7, "Newton's method failed with ds < ds_min"
    left_parameter_range = 8, "the parameter left [p_min, p_max]"
    energy_balance_failed = 9, ("energy balance failed: the friction work minus the "
                                "viscous dissipation misses the change of mechanical "
                                "energy far beyond the tolerance; tighten rtol and atol")

    def __str__(self) -> str:
        return self.name


#: The statuses of a trajectory, as its arrays and files hold them.
RUN_STATUSES = (Status.not_run, Status.ok, Status.max_steps_reached,
                Status.solver_failed, Status.non_finite_state,
                Status.step_size_collapsed, Status.event_not_resolved,
                Status.energy_balance_failed)


#: A run whose energy balance misses (`energy_balance`) by more than
#: BALANCE_TOLERANCES times its tolerance max(rtol, atol), at most BALANCE_LIMIT,
#: is `Status.energy_balance_failed`; for the smoothed engine the bound is at least
#: SMOOTHED_BALANCE_FLOOR: its work integrals are not error-controlled
#: (`_with_work`), and their miss near the stick/slip switches does not fall with
#: rtol: 3e-3 to 4e-3 at the defaults (eps 1e-3, rtol 3e-5), 4e-4 to 6e-4 at eps
#: 1e-5 and 3e-5 to 5e-5 at eps 1e-7 with the tolerances that follow eps (four
#: oscillators excited 1 ... 4, t_end 300), while rtol 1e-2 and 3e-2 at eps 1e-2
#: (one oscillator from rest, energies off by a factor 3 and 25) miss by 0.047 and
#: 0.094. The exact engine's miss is 2e-6 at its defaults, 0.78 at rtol 0.1.
BALANCE_TOLERANCES, BALANCE_LIMIT, SMOOTHED_BALANCE_FLOOR = 1000.0, 0.02, 0.02


def energy_balance(params: ChainParams, y0, y1, friction_work, dissipation):
    """The relative miss of the energy balance of a run from the state `y0` to `y1`
    (shape (2, n_osc)): |E(y1) - E(y0) - (W - D)| / (E(y0) + E(y1) + |W| + D), E the
    `mechanical_energy`, W the friction work int sum_n F_n x_n' dt and D the viscous
    dissipation int sum_n 2 xi_n x_n'^2 dt over the run (|D| in the denominator: a
    run far from its tolerance can integrate D < 0). The denominator is the energy
    that went through the chain: the miss is at most 1. Shape ()."""
    e0, e1 = mechanical_energy(params, y0), mechanical_energy(params, y1)
    return (jnp.abs(e1 - e0 - (friction_work - dissipation))
            / (e0 + e1 + jnp.abs(friction_work) + jnp.abs(dissipation)))


def balance_status(status, params: ChainParams, y0, y1, friction_work, dissipation,
                   rtol, atol, floor: float = 0.0):
    """`status`, or `Status.energy_balance_failed` for a run that is otherwise ok
    and whose `energy_balance` misses by more than `BALANCE_TOLERANCES` max(rtol,
    atol) clipped to [`floor`, `BALANCE_LIMIT`] (a non-finite miss included)."""
    miss = energy_balance(params, y0, y1, friction_work, dissipation)
    tolerance = jnp.maximum(jnp.max(jnp.asarray(rtol)), jnp.max(jnp.asarray(atol)))
    limit = jnp.clip(BALANCE_TOLERANCES * tolerance, floor, BALANCE_LIMIT)
    failed = (status == Status.ok) & ~(miss <= limit)
    return jnp.where(failed, Status.energy_balance_failed, status)


def status_names(codes) -> np.ndarray:
    """The member names of integer status codes, elementwise (for tables)."""
    codes = np.asarray(codes)
    return np.vectorize(lambda c: Status(int(c)).name, otypes=[object])(codes)


def flag_attributes(statuses=RUN_STATUSES) -> dict:
    """CF attributes of a status variable (CF conventions, section 3.5, flags):
    `flag_values`, `flag_meanings` (the member names, blank-separated) and a
    `comment` with each member's message."""
    return {"flag_values": np.array([int(s) for s in statuses], dtype=np.int64),
            "flag_meanings": " ".join(s.name for s in statuses),
            "comment": "; ".join(f"{s.name}: {s.message}" for s in statuses)}


#: Stability bound of an explicit Runge-Kutta step on a decaying mode, h |lambda| <~
#: 3 (Tsit5, Dopri5: 3.3 and 3.3 on the negative real axis; Hairer & Wanner,
#: Solving ODEs II, IV.2).
EXPLICIT_STABILITY = 3.0


def _name(solver) -> str:
    for name, make in SOLVERS.items():
        made = make() if callable(make) else make
        if type(made) is type(solver):
            return name
    return type(solver).__name__


def _explicit(solver) -> bool:
    return not isinstance(solver, (diffrax.AbstractImplicitSolver,
                                   SOLVERS[DEFAULT_SOLVER]))


def failure_hint(status: int, params: ChainParams, solver: diffrax.AbstractSolver,
                 options: SimulationOptions, eps) -> str:
    """A hint for a trajectory of `status`, naming the setting to change.

    **Arguments:**

    - `status`: the `Status` of the run (or its integer value).
    - `params`, `solver`, `options`, `eps`: those of the run (the chain, the smoothed
        engine's solver, options and smoothing velocity).

    **Returns:**

    One sentence; "" for `Status.ok`, and the member's message for a status that
    has no hint of its own.
    """
    status = Status(int(status))
    options = follow_eps(options, eps)  # tolerances left None: those of the run
    stiffness = stick_stiffness(params, eps)
    eps = float(np.max(np.asarray(eps)))
    name = _name(solver)
    stiff = (f"eps = {eps:g} makes the stick phase stiff (stiffness mu_st/eps = "
             f"{stiffness:.3g})")
    if status is Status.ok:
        return ""
    if status is Status.max_steps_reached:
        if _explicit(solver):
            step = EXPLICIT_STABILITY / stiffness
            return (f"{stiff}: an explicit solver ({name}) may need steps as small as "
                    f"3 eps/mu_st = {step:.1g} while it sticks; use "
                    f"solver='{DEFAULT_SOLVER}' (or 'auto'), or eps >= {10 * eps:g}")
        return (f"{name} ran out of its {options.max_steps} steps in one chunk of "
                f"length {options.chunk_length:g} ({stiff}); raise max_steps, shorten "
                f"chunk_length or use eps >= {10 * eps:g}")
    if status is Status.solver_failed:
        return (f"{name}'s implicit stage solve failed ({stiff}); use "
                f"solver='{DEFAULT_SOLVER}', whose linearly implicit steps need no "
                f"Newton iteration, or tighter tolerances")
    if status is Status.non_finite_state:
        return ("the state became non-finite: check that the initial state is finite, "
                "and that the parameters are within the ranges of ChainParams")
    if status is Status.step_size_collapsed:
        other = "" if name == DEFAULT_SOLVER else f"solver='{DEFAULT_SOLVER}', "
        return (f"{stiff}, and the steps fell below dtmin = {options.dtmin:g} on "
                f"average until max_steps ran out; use {other}eps >= {10 * eps:g}, "
                f"looser rtol (now {float(np.max(np.asarray(options.rtol))):g}) or a "
                f"smaller dtmin")
    return status.message
