"""The first Lyapunov coefficient of the Hopf bifurcation of steady sliding."""

import itertools

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
from jaxtyping import Array, Float

from .._engine.compat import checks_as_nan
from .._engine.engines import AbstractEngine, Smoothed
from .._physics.params import ChainParams
from .hopf import check_engine, critical_mode


def _derivative(params: ChainParams, engine, y, vectors) -> Array:
    """The multilinear form d^k f(y)[v_1, ..., v_k] of the flattened vector field
    of `engine`'s model (`AbstractEngine.field`), by nested forward-mode
    derivatives (real vectors)."""
    def f(z):
        return jnp.reshape(engine.field(params, jnp.reshape(z, (2, -1))), (-1,))

    for v in vectors:
        f = (lambda g, v: lambda z: jax.jvp(g, (z,), (v,))[1])(f, v)
    return f(y)


def _complex_form(params: ChainParams, engine, y, vectors) -> Array:
    """The multilinear form for complex vectors, expanded into real and imaginary
    parts (forward-mode tangents are real)."""
    out = 0.0
    for parts in itertools.product((0, 1), repeat=len(vectors)):
        real = [(v.imag if part else v.real) for v, part in zip(vectors, parts)]
        out = out + (1j ** sum(parts)) * _derivative(params, engine, y, real)
    return out


def first_lyapunov_coefficient(params: ChainParams, mode: int = 0, *,
                               engine: AbstractEngine = Smoothed()) -> Float[Array, ""]:
    """The first Lyapunov coefficient l1 of the Hopf bifurcation of steady sliding
    in Fourier mode `mode`, at `params.v_d` (pass the Hopf point's v_d):

        l1 = 1/(2 omega) Re[<p, C(q, q, conj q)> - 2 <p, B(q, A^-1 B(q, conj q))>
                            + <p, B(conj q, (2 i omega - A)^-1 B(q, q))>],

    Kuznetsov, *Elements of Applied Bifurcation Theory* (3rd ed., 2004), eq.
    (3.20), with A q = i omega q, A^T p = -i omega p, <p, q> = <q, q> = 1. A is the
    Jacobian of eq. (5) (`AbstractEngine.jacobian` at steady sliding), B and C its
    second and third derivatives (nested `jax.jvp`), the linear solves by lineax. l1 > 0: subcritical (an
    unstable cycle surrounds stable steady sliding); l1 < 0: supercritical.

    For the ring the in-phase mode (`mode=0`) is the one to ask: its subspace
    (all x_n equal) is invariant and carries the single oscillator. At the ring's
    Hopf point all modes are critical together, so l1 of one mode does not
    describe the whole centre manifold.

    For one oscillator with sign() friction, l1 = F'''(-v_d)/8 = xi / (4 v0^2) at
    the Hopf point (0.05 for eq. (7)), and the small cycle has amplitude
    sqrt(8 v0 (v_d - v_d,H)). In the ring, <q, q> = 1 spreads the mode over N
    oscillators and the in-phase l1 is the single oscillator's divided by N.

    **Arguments:**

    - `params`: the chain parameters, at the Hopf point.
    - `mode`: Fourier mode k with a real mode shape, 0 or N/2, on the homogeneous
        ring; 0 (the leading eigenvalue, `critical_mode`) on any other chain.
    - `engine`: the engine whose model is expanded: `Smoothed()` (eps = 1e-3) by
        default, smoothed at its `Smoothed.eps`; `Exact()` gives the limit eps ->
        0 (the slip law). Pass that of the Hopf point (`hopf_point`).

    **Returns:**

    l1, shape (), dimensionless.

    **Raises:**

    `ValidationError` for a bad mode; `TypeError` for an `engine` that is not one.
    """
    return _first_lyapunov_coefficient(params, mode, check_engine(engine))


@checks_as_nan
@eqx.filter_jit
def _first_lyapunov_coefficient(params: ChainParams, mode: int, engine
                                ) -> Float[Array, ""]:
    """`first_lyapunov_coefficient` as one compiled program (not op by op)."""
    n = params.n_osc
    omega, q, p = critical_mode(params, mode, engine)

    y = jnp.reshape(engine.steady_sliding(params), (-1,))
    a = engine.jacobian(params).astype(complex)

    def solve(matrix, vector):
        # throw=False: a singular system gives NaN either way, and lineax's check
        # (built at lowering) would be a host callback wherever this is compiled
        # outside checks_as_nan (inside a user's own jax.jit)
        return lx.linear_solve(lx.MatrixLinearOperator(matrix), vector, lx.LU(),
                               throw=False).value

    def inner(u, v):
        return jnp.vdot(u, v)

    c = _complex_form(params, engine, y, [q, q, q.conj()])
    b1 = solve(a, _complex_form(params, engine, y, [q, q.conj()]))
    b2 = solve(2j * omega * jnp.eye(2 * n) - a, _complex_form(params, engine, y, [q, q]))
    value = (inner(p, c) - 2 * inner(p, _complex_form(params, engine, y, [q, b1]))
             + inner(p, _complex_form(params, engine, y, [q.conj(), b2])))
    return value.real / (2 * omega)
