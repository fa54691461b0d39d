"""Stick and slip modes of the exact engine: the vector field within a mode, the
guard whose zero is a switch, and the switching rule applied there.

Each oscillator has a mode s_n: +1 or -1 in slip (the sign of x_n' - v_d), 0 in
stick. Between switches the modes are fixed and the vector field is smooth. The
guard of each oscillator is

- s_n (x_n' - v_d) in slip (slip ends when it reaches zero),
- (P_n/P) mu(0) - |f_n| in stick (stick ends when the needed force f_n of
  `stick_force` reaches the static friction `static_friction`, mu_st for eq. (1)),

each positive while nothing happens. The smallest guard's first fall through zero
is the first switch of any oscillator, so one scalar function locates the earliest
switch however many oscillators there are.
"""

import jax
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


#: Offset that makes every guard strictly positive after a switch, which has just
#: set it to exactly zero: a switch is a step whose guard ends <= 0, so a guard
#: starting at 0 could hide the next one.
_OFFSET = 1e-15


def _stick_force_rate(params, v):
    """d f_n / dt along the motion (f is affine in x)."""
    return stick_force(params, v) - 2 * params.xi * params.v_d


def switch_guards(params, y, modes, held=()):
    """Each oscillator's guard (see the module docstring), > 0 while nothing
    happens, shape (n_osc,); +inf for the oscillators `held` (indices) in their
    mode, which never switch."""
    x, v = y
    f = stick_force(params, x)
    g = _OFFSET + jnp.where(modes == 0, static_friction(params) - jnp.abs(f),
                            modes * (v - params.v_d))
    return g if not held else g.at[jnp.asarray(held)].set(jnp.inf)


def guard(params, y, modes, held=()):
    """The smallest guard, a scalar: its fall through zero is the next switch."""
    return jnp.min(switch_guards(params, y, modes, held))


def switch(params, y, modes, tol, held=()):
    """Apply the switching rule at a switch.

    An oscillator switches when its guard lies within `tol` of zero and is
    decreasing (so that a phase that has just begun is not ended again):

    - stick ends (mu_st - |f_n| <= tol, |f_n| growing): slip in direction
      -sign(f_n), the direction in which the unbalanced force accelerates it;
    - slip ends (s_n (x_n' - v_d) <= tol, decelerating): stick if |f_n| < mu_st;
      otherwise the force needed to stick exceeds static friction, and slip
      reverses to direction -sign(f_n), through v_rel = 0.

    Switching oscillators get x_n' = v_d exactly (a change of at most `tol`), so
    that every guard starts the next step above zero. Because f_n depends on
    displacements only, the decisions are independent of one another:
    simultaneous switches need no ordering.

    **Returns:**

    (y, modes, kind, resolved): the projected state, the new modes, the kind of
    switch of each oscillator (an index into `SWITCH_KINDS`, -1 for none), and
    whether any oscillator switched.
    """
    x, v = y
    a = mode_field(0.0, (y, None), (params, modes))[0][1]
    f = stick_force(params, x)
    stick = modes == 0
    due = switch_guards(params, y, modes, held) <= tol
    leaves = stick & due & (jnp.sign(f) * _stick_force_rate(params, v) >= 0)
    ends = ~stick & due & (modes * a <= 0)
    sticks = ends & (jnp.abs(f) < static_friction(params))
    reverses = ends & ~sticks
    new_modes = jnp.where(leaves | reverses, -jnp.sign(f), jnp.where(sticks, 0.0, modes))
    v = jnp.where(leaves | ends, params.v_d, v)
    kind = jnp.where(leaves, 0, jnp.where(sticks, 1, jnp.where(reverses, 2, -1)))
    return jnp.stack([x, v]), new_modes, kind, jnp.any(leaves | ends)


def initial_modes(params, y):
    """Modes at the start of a run: stick where x_n' = v_d exactly and |f_n| < mu_st,
    otherwise slip in the direction of x_n' - v_d (or of -f_n when exactly at the
    belt speed)."""
    x, v = y
    f = stick_force(params, x)
    v_rel = v - params.v_d
    return jnp.where(v_rel == 0, jnp.where(jnp.abs(f) < static_friction(params), 0.0, -jnp.sign(f)),
                     jnp.sign(v_rel))


def saltation_matrix(params, y, modes_before, modes_after, osc):
    """The saltation matrix of one oscillator's switch: how a perturbation of the
    state just before the switch maps to one just after it (Leine and Nijmeijer,
    *Dynamics and Bifurcations of Non-Smooth Mechanical Systems*, 2004, Section
    7.1; Aizerman and Gantmacher 1958),

        S = I + (f+ - f-) h_y^T / (h_y^T f-),

    with f- and f+ the vector fields of the modes before and after, h the
    switching oscillator's guard in the mode before (`switch_guards`), all at
    the switch point. The state is flattened as (x_1..x_n, x_1'..x_n').

    - slip to stick: S = I - e_v e_v^T for the oscillator's velocity v: stick
        fixes x_n' = v_d, and a perturbation of x_n' is lost;
    - stick to slip: S = I when the friction law is continuous at v_rel = 0
        (the slip force there is the static friction that stick had reached);
    - slip reversal: the acceleration jumps by twice the static friction, and S
        differs from I in the oscillator's velocity column.

    The exact engine applies these without forming them (its derivatives go
    through each switch time by the implicit function theorem); this function is
    the check and the building block of a monodromy matrix.

    **Arguments:**

    - `params`: the chain parameters.
    - `y`: the state at the switch, shape (2, n_osc).
    - `modes_before`, `modes_after`: the modes (+1/-1 slip, 0 stick), shape
        (n_osc,).
    - `osc`: the switching oscillator (index from 0).

    **Returns:**

    S, shape (2 n_osc, 2 n_osc).
    """
    shape = y.shape

    def field(modes):
        return mode_field(0.0, (y, None), (params, modes))[0].reshape(-1)

    h_y = jax.grad(lambda z: switch_guards(params, z.reshape(shape), modes_before)[osc])(
        y.reshape(-1))
    f_before = field(modes_before)
    jump = field(modes_after) - f_before
    return jnp.eye(y.size) + jnp.outer(jump, h_y) / jnp.dot(h_y, f_before)
