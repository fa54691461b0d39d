"""Stick and slip modes of the non-smooth reference: the vector field within a mode,
the guard whose zero ends a segment, and the switching rule applied at an event.

Each oscillator has a mode s_n: +1 or -1 in slip (the sign of x_n' - v_d), 0 in
stick. Within a segment the modes are fixed, the vector field is smooth, and the
guard is the smallest of

- s_n (x_n' - v_d) for oscillators in slip (slip ends when it reaches zero),
- (P_n/P) mu(0) - |f_n| for oscillators in stick (stick ends when the needed
  force f_n of `stick_force` reaches the static friction `static_friction`,
  mu_st for eq. (1)),
- tol + sigma_n x_n' for oscillators in slip while observing, sigma_n the
  direction of motion (a turning point: an extremum of x_n, from which the
  amplitudes are taken without sampling error),

each positive while nothing happens. The smallest guard's first down-crossing is
the first event of any oscillator, so one scalar event function locates the
earliest event however many oscillators there are.
"""

import jax.numpy as jnp

from ..._physics.forces import coupling_force, slip_friction_force, static_friction
from ..._physics.model import stick_force

#: Kinds of switch recorded in the event log.
SWITCH_KINDS = ("stick to slip", "slip to stick", "slip reversal")


def mode_field(t, state, args):
    """Vector field of the chain with fixed modes, and the power balance.

    `state` is (y, work): y of shape (2, n_osc) as in `vector_field`, work of shape
    (2,) holding the friction work int sum_n F_n x_n' dt and the viscous
    dissipation int sum_n 2 xi x_n'^2 dt. In stick x_n' = v_d, x_n'' = 0 and the
    friction force is f_n; in slip eq. (5) holds with `slip_friction_force`.
    """
    y, _ = state
    params, modes = args[0], args[1]
    x, v = y
    stick = modes == 0
    force = jnp.where(stick, stick_force(params, x),
                      slip_friction_force(params, v - params.v_d, modes))
    dx = jnp.where(stick, params.v_d, v)
    a = -2 * params.xi * v - params.stiffness * x - coupling_force(params, x) + force
    if params.mass is not None:
        a = a / params.mass
    a = jnp.where(stick, 0.0, a)
    power = jnp.stack([jnp.sum(force * dx), jnp.sum(2 * params.xi * dx**2)])
    return jnp.stack([dx, a]), power


#: Offset that makes every guard strictly positive at the start of a segment, where
#: a switch has just set it to exactly zero: diffrax triggers on a step whose
#: previous guard value is > 0, so a guard starting at 0 could hide the next event.
_OFFSET = 1e-15


def _stick_force_rate(params, v):
    """d f_n / dt along the motion (f is affine in x)."""
    return stick_force(params, v) - 2 * params.xi * params.v_d


def turning_directions(params, y, modes, tol):
    """Direction of motion sigma_n (+1, -1) of each slipping oscillator at the start
    of a segment: the sign of x_n' where |x_n'| > tol, else the sign of x_n''. Zero
    where the oscillator sticks."""
    v = y[1]
    a = mode_field(0.0, (y, None), (params, modes))[0][1]
    sigma = jnp.where(jnp.abs(v) > tol, jnp.sign(v), jnp.sign(a))
    return jnp.where(modes == 0, 0.0, sigma)


def _guard_values(params, y, modes, sigma, observe, tol):
    """Per-oscillator guards (switch, turning), each > 0 while nothing happens; +inf
    where a guard does not apply.

    A turning point is detected once x_n' has passed zero by `tol` (sigma_n x_n' =
    -tol). This places the extremum within tol^2 / (2 |x_n''|) of the true one
    (1e-18 for the default tol), and it ignores oscillations whose velocity stays
    below tol, which integration noise would otherwise turn into spurious events.
    """
    x, v = y
    f = stick_force(params, x)
    switch = _OFFSET + jnp.where(modes == 0, static_friction(params) - jnp.abs(f),
                                 modes * (v - params.v_d))
    turning = jnp.where(observe & (sigma != 0), tol + sigma * v, jnp.inf)
    return switch, turning


def guard(t, y, args, **kwargs):
    """The event function: the smallest guard, a scalar (see the module docstring).
    `y` is the (state, work) pair of `mode_field`; `args` is (params, modes, sigma,
    observe, tol)."""
    switch, turning = _guard_values(args[0], y[0], *args[1:])
    return jnp.minimum(jnp.min(switch), jnp.min(turning))


def switch(params, y, modes, sigma, observe, tol):
    """Apply the switching rule at an event.

    An oscillator switches when its guard lies within `tol` of zero and is
    decreasing (so that a phase that has just begun is not ended again):

    - stick ends (mu_st - |f_n| <= tol, |f_n| growing): slip in direction
      -sign(f_n), the direction in which the unbalanced force accelerates it;
    - slip ends (s_n (x_n' - v_d) <= tol, decelerating): stick if |f_n| < mu_st;
      otherwise the force needed to stick exceeds static friction, and slip
      reverses to direction -sign(f_n), through v_rel = 0;
    - a turning point (its guard of `_guard_values` within tol of zero,
      decelerating) gives an extremum.

    Switching oscillators get x_n' = v_d exactly (a change of at most `tol`), so
    that every guard starts the next segment above zero. Because f_n depends on
    displacements only, the decisions are independent of one another:
    simultaneous switches need no ordering.

    **Returns:**

    (y, modes, kind, turned, resolved): the projected state, the new modes, the
    kind of switch of each oscillator (an index into `SWITCH_KINDS`, -1 for none), the
    turning-point mask, and whether anything happened at all.
    """
    x, v = y
    a = mode_field(0.0, (y, None), (params, modes))[0][1]
    f = stick_force(params, x)
    switch_guard, turning_guard = _guard_values(params, y, modes, sigma, observe, tol)
    stick = modes == 0
    due = switch_guard <= tol
    leaves = stick & due & (jnp.sign(f) * _stick_force_rate(params, v) >= 0)
    ends = ~stick & due & (modes * a <= 0)
    sticks = ends & (jnp.abs(f) < static_friction(params))
    reverses = ends & ~sticks
    new_modes = jnp.where(leaves | reverses, -jnp.sign(f), jnp.where(sticks, 0.0, modes))
    turned = (turning_guard <= tol) & (sigma * a <= 0) & ~ends
    v = jnp.where(leaves | ends, params.v_d, v)
    kind = jnp.where(leaves, 0, jnp.where(sticks, 1, jnp.where(reverses, 2, -1)))
    resolved = jnp.any(leaves | ends | turned)
    return jnp.stack([x, v]), new_modes, kind, turned, resolved


def initial_modes(params, y):
    """Modes at the start of a run: stick where x_n' = v_d exactly and |f_n| < mu_st,
    otherwise slip in the direction of x_n' - v_d (or of -f_n when exactly at the
    belt speed)."""
    x, v = y
    f = stick_force(params, x)
    v_rel = v - params.v_d
    return jnp.where(v_rel == 0, jnp.where(jnp.abs(f) < static_friction(params), 0.0, -jnp.sign(f)),
                     jnp.sign(v_rel))
