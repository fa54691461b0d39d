"""When an oscillator sticks: the one definition of the high-amplitude limit cycle
(HALC, the stick-slip cycle) shared by the smoothed runs, shooting and the
non-smooth reference."""

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

#: Half-width of the stick band, in units of eps: an oscillator sticks while its
#: slip speed |x' - v_d| <= STICK_BAND * eps. Outside the band the smoothed law
#: tanh(v_rel/eps) is within 1 - tanh(3) = 0.5 % of sign(v_rel) (slip); inside it,
#: the friction force balances any needed force |f| <= tanh(3) mu_st = 0.995 mu_st
#: at the slip speed eps artanh(|f| / mu_st) (stick).
STICK_BAND = 3.0


def min_slip_speed(v: Float[ArrayLike, "samples n_osc"], v_d: Float[ArrayLike, ""]
                   ) -> Float[Array, " n_osc"]:
    """Smallest slip speed |x_n' - v_d| of each oscillator over samples of its
    velocity: the running reduction from which `sticks` decides.

    **Arguments:**

    - `v`: velocities x_n' at sampled times, shape (samples, n_osc), dimensionless.
    - `v_d`: belt speed, dimensionless.

    **Returns:**

    min over the samples of |x_n' - v_d|, shape (n_osc,).
    """
    return jnp.min(jnp.abs(jnp.asarray(v) - v_d), axis=0)


def sticks(slip_speed: Float[ArrayLike, "*shape"], eps: Float[ArrayLike, ""]
           ) -> Bool[Array, "*shape"]:
    """Whether an oscillator sticks, and so lies on the HALC: its smallest slip
    speed over the observed window enters the stick band,

        min_t |x_n'(t) - v_d| <= STICK_BAND * eps.

    The band is where the smoothed friction -mu tanh(v_rel/eps) (eq. (2) of the
    paper with sign smoothed) acts as stick: there it is more than 0.5 % away from
    its saturated (slip) value and balances the force the oscillator needs, at
    |v_rel| = eps artanh(|f| / mu_st) <= 3 eps for |f| <= 0.995 mu_st. In a
    stick-slip cycle at eps = 1e-3 the slip speed falls to about 0.3 eps; a sliding
    or small-amplitude oscillator stays at |v_rel| ~ v_d - A, about 1000 eps. For
    the non-smooth reference eps = 0: the band is v_rel = 0, held in stick, so the
    test is "stuck at least once".

    A slip reversal (v_rel passing through 0 with |f| > mu_st, not stick) crosses
    the band in about 2 STICK_BAND eps / |f| <= 0.006 time units; the sampled
    smoothed minimum may catch it; the reference locates it at |v_rel| of about
    its event tolerance, not 0, and does not count it. No reversal
    occurred in the states measured (N = 20, v_d = 1.2 - 1.75).

    **Arguments:**

    - `slip_speed`: smallest |x_n' - v_d| over the window (`min_slip_speed`), any
        shape, dimensionless.
    - `eps`: smoothing of the friction law (0 for the non-smooth reference).

    **Returns:**

    Boolean array of the shape of `slip_speed`; False where it is NaN (a failed run).
    """
    return jnp.asarray(slip_speed) <= STICK_BAND * eps
