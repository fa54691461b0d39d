"""Options of a simulation run: horizon, tolerances and how observables are sampled,
and the rule that ties the smoothed engine's tolerances to eps."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .horizon import AbstractHorizon, positive
from .solver.controller import CONTROLLERS
from .._checks import check_count
from .._physics.friction import concrete
from .._errors import ValidationError


class SimulationOptions(AbstractHorizon):
    """How long to integrate, how accurately, and how to observe: the horizon of
    `AbstractHorizon` with the smoothed engine's tolerances and sampling.

    All fields but the tolerances are static: changing one recompiles. `rtol` and
    `atol` may be given as JAX arrays, so that a sweep over tolerances compiles
    once (Python floats are static like the other fields). Times are dimensionless, in units
    of 1/omega_n (eq. (4) of the paper).

    **Arguments:**

    - `t_end`: final time. The paper's default is 15000.
    - `transient`: observables are taken over [transient, t_end]. The paper's
        default is 10000 (Section 3.2).
    - `rtol`, `atol`: tolerances of the step-size controller, each in (0, 1).
        None (the default) follows eps: the smoothed engine takes
        `follow_eps` = min(3e-5, eps/30) and min(3e-7, eps/3000), so that the
        error allowed per step stays well inside the stick band (|v_rel| <= 3
        eps). At the default eps = 1e-3 these are 3e-5 and 3e-7, the loosest at
        which the cross-check holds (every n_HALC agrees with the non-smooth
        reference; at 1e-4 the states near the fold of existence, v_d = 1.75,
        decay): the integration error is then below the error of the smoothing
        (documentation, "Performance"). A value given is kept, but the engine
        refuses one that cannot resolve the stick band (`check_stick_band`).
    - `controller`: the step-size controller, "pi" (`PIController`, the default)
        or "diffrax" (diffrax's `PIDController` as an integral controller, the
        controller jaxchain used first); see `CONTROLLERS`.
    - `sample_dt`: spacing of the dense-output samples from which the extrema are
        taken. An extremum of a smooth slip phase is missed by at most
        |x''| sample_dt^2 / 8 ~ A sample_dt^2 / 8, a relative 3e-4 for the default
        0.05, below the 1e-3 resolution asked of the amplitudes.
    - `chunk_length`: the run is integrated in chunks of about this length; the
        samples of one chunk are reduced before the next starts, so memory is fixed
        by `chunk_length / sample_dt`, never by `t_end`.
    - `max_steps`: step budget of one chunk.
    - `dtmin`: a run that spends a chunk's `max_steps` on steps shorter than this
        on average fails with `Status.step_size_collapsed` rather than
        `Status.max_steps_reached`: its steps have stopped advancing t (at t = 15000
        a float64 resolves 2e-12). It does not limit the step-size controller,
        whose steps are those of diffrax's `PIDController` alone.

    Which oscillators are on the HALC is not an option: it is the one definition of
    `sticks`, shared with shooting and the non-smooth reference.

    **Raises:**

    `ValidationError` naming the field for t_end <= 0, transient outside [0, t_end),
    tolerances outside (0, 1), non-positive or non-finite sample_dt, chunk_length,
    max_steps or dtmin, and a controller not in `CONTROLLERS`.
    """

    t_end: float = eqx.field(static=True, default=15000.0)
    transient: float = eqx.field(static=True, default=10000.0)
    rtol: float | None = None
    atol: float | None = None
    controller: str = eqx.field(static=True, default="pi")
    sample_dt: float = eqx.field(static=True, default=0.05)
    chunk_length: float = eqx.field(static=True, default=250.0)
    max_steps: int = eqx.field(static=True, default=200_000)
    dtmin: float = eqx.field(static=True, default=1e-10)

    def __check_init__(self):
        check_tolerances("SimulationOptions", self.rtol, self.atol, follows=True)
        for name in ("sample_dt", "max_steps", "dtmin"):
            value = getattr(self, name)
            if not positive(value):
                raise ValidationError(f"SimulationOptions.{name} must be a finite number > 0, "
                                      f"got {value!r}")
        if self.controller not in CONTROLLERS:
            raise ValidationError(f"SimulationOptions.controller must be one of "
                                  f"{', '.join(CONTROLLERS)}, got {self.controller!r}")
        check_count("SimulationOptions.max_steps", self.max_steps)
        self.check_horizon()


#: The tolerances of the smoothed engine at `DEFAULT_EPS` = 1e-3 (`follow_eps`).
DEFAULT_RTOL, DEFAULT_ATOL = 3e-5, 3e-7

#: The smoothed engine's tolerances where none is given: rtol <= eps / RTOL_PER_EPS,
#: atol <= eps / ATOL_PER_EPS (`follow_eps`). The velocity error allowed per step,
#: about rtol v_d, then stays a small fraction of the stick band |v_rel| <= 3 eps.
RTOL_PER_EPS, ATOL_PER_EPS = 30.0, 3000.0

#: The loosest tolerances that resolve the stick band (`check_stick_band`): rtol and
#: atol <= STICK_BAND_RTOLS eps. Measured on four oscillators excited 1 ... 4 (v_d =
#: 1.5, docs/solvers.md): at rtol = 100 eps the slowest slip of a sticking
#: oscillator reaches 1.4 eps, half the band; at 300 eps and beyond (eps = 1e-7,
#: 1e-8 and 1e-10 at rtol 3e-5) sticking oscillators are counted as sliding.
STICK_BAND_RTOLS = 100.0


def check_tolerances(owner: str, rtol, atol, *, follows: bool = False) -> None:
    """Refuse a tolerance that is not a number in (0, 1) (None too, unless it
    `follows` eps): a relative error of 1 or more controls nothing (rtol = atol = 10
    gave an energy of 1e83 with a successful status).

    **Raises:**

    `ValidationError` naming `owner.rtol` or `owner.atol` and the value.
    """
    for name, value in (("rtol", rtol), ("atol", atol)):
        if value is None and follows:
            continue
        if not (positive(value) and np.all(np.asarray(value) < 1)):
            raise ValidationError(f"{owner}.{name} must be a number in (0, 1), got "
                                  f"{value!r}")


def follow_eps(options: SimulationOptions, eps) -> SimulationOptions:
    """`options` with the tolerances left None set from the smoothing velocity `eps`:
    rtol = min(`DEFAULT_RTOL`, eps / `RTOL_PER_EPS`), atol = min(`DEFAULT_ATOL`,
    eps / `ATOL_PER_EPS`) (at the default eps = 1e-3 exactly the defaults, Python
    floats). For an `eps` that is not concrete (traced) they are JAX arrays, outside
    the derivative. The tolerances given are kept; an eps that is not a number > 0
    leaves them as they are (the engine's check of eps names it)."""
    try:
        value = concrete(eps)
    except (TypeError, ValueError):
        return options
    if value is not None and not (value.size and np.all(np.isfinite(value) & (value > 0))):
        return options

    def follow(default, per_eps):
        if value is None:
            return jnp.minimum(default, jax.lax.stop_gradient(eps) / per_eps)
        return min(default, float(np.min(value)) / per_eps)

    rtol = follow(DEFAULT_RTOL, RTOL_PER_EPS) if options.rtol is None else options.rtol
    atol = follow(DEFAULT_ATOL, ATOL_PER_EPS) if options.atol is None else options.atol
    return eqx.tree_at(lambda o: (o.rtol, o.atol), options, (rtol, atol),
                       is_leaf=lambda x: x is None)


def check_stick_band(options: SimulationOptions, eps) -> None:
    """Refuse tolerances that cannot resolve the stick band |v_rel| <= 3 eps, in
    which an oscillator counts as sticking (`sticks`): rtol or atol >
    `STICK_BAND_RTOLS` eps (the error allowed per step in x' is atol + rtol |x'|,
    and |x'| = v_d ~ 1 in stick). Values that are not concrete (traced) are not
    checked.

    **Raises:**

    `ValidationError` naming `SimulationOptions.rtol` (or `.atol`) and the largest
    value that resolves the band.
    """
    values = [concrete(v) for v in (eps, options.rtol, options.atol)]
    if any(v is None for v in values):
        return
    eps, rtol, atol = (float(np.max(v)) for v in values)
    limit = STICK_BAND_RTOLS * eps * (1 + 1e-9)  # 100 * 1e-5 rounds above 1e-3
    for name, value in (("rtol", rtol), ("atol", atol)):
        if value > limit:
            raise ValidationError(
                f"SimulationOptions.{name} = {value:g} cannot resolve the stick band "
                f"(|v_rel| <= 3 eps) at eps = {eps:g}: it must be at most "
                f"{STICK_BAND_RTOLS:g} eps = {limit:.3g}; leave rtol and atol unset to "
                f"follow eps (rtol = eps/{RTOL_PER_EPS:g}), or take a larger eps")
