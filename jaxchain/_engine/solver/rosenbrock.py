"""ROS34PW2, a linearly implicit Rosenbrock-W method whose W matrix is diagonal, as
a diffrax solver.

The stiffness of eq. (5) sits in the friction force, and the friction on oscillator
n depends on x_n' only: its Jacobian is diagonal. A W-method keeps its order for
any approximation W of the Jacobian, so W = I - h gamma diag(d), built from that
diagonal, turns every stage's linear solve into an elementwise division: no Newton
iteration, no LU factorisation, no LAPACK call in the step loop.
"""

from collections.abc import Callable
from typing import ClassVar

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

# ROS34PW2 of Rang & Angermann (2005), "New Rosenbrock W-methods of order 3 for
# partial differential algebraic equations of index 1", BIT 45, 761-787, Table 4.1:
# 4 stages, order 3 for any W (a W-method), embedded order 2, stiffly accurate and
# L-stable. The tableau in the paper's form:
#   (I - h gamma J) k_i = h f(y0 + sum_j alpha_ij k_j) + h J sum_j gamma_ij k_j,
#   y1 = y0 + sum_i b_i k_i.
_GAMMA = 0.435866521508459
_ALPHA = np.array([
    [0.0, 0.0, 0.0, 0.0],
    [0.87173304301691801, 0.0, 0.0, 0.0],
    [0.84457060015369423, -0.11299064236484185, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
])
_GAMMAS = np.array([
    [_GAMMA, 0.0, 0.0, 0.0],
    [-0.87173304301691801, _GAMMA, 0.0, 0.0],
    [-0.90338057013044082, 0.054180672388095326, _GAMMA, 0.0],
    [0.24212380706095346, -1.2232505839045147, 0.54526025533510214, _GAMMA],
])
_B = np.array([0.24212380706095346, -1.2232505839045147, 1.5452602553351020, _GAMMA])
_B_EMBEDDED = np.array([0.37810903145819369, -0.096042292212423178, 0.5,
                        0.2179332607542295])

# The same method in the variables u_i = sum_j gamma_ij k_j (Hairer & Wanner,
# "Solving ODEs II", Section IV.7), which need no product with the Jacobian:
#   (1/(h gamma) - J) u_i = f(y0 + sum_j a_ij u_j) + sum_j c_ij u_j / h,
#   y1 = y0 + sum_i m_i u_i.
_GAMMA_INV = np.linalg.inv(_GAMMAS)
_A = _ALPHA @ _GAMMA_INV
_C = np.diag(1.0 / np.diag(_GAMMAS)) - _GAMMA_INV
_M = _B @ _GAMMA_INV
_M_ERROR = (_B - _B_EMBEDDED) @ _GAMMA_INV


class Ros34PW2(diffrax.AbstractAdaptiveSolver):
    """ROS34PW2 (Rang & Angermann 2005, BIT 45, 761-787), a 4-stage linearly
    implicit Rosenbrock-W method of order 3 with an embedded order-2 error estimate,
    L-stable and stiffly accurate, whose W matrix is diagonal.

    Takes `terms = MultiTerm(ODETerm(f_explicit), ODETerm(f_stiff))`, like diffrax's
    IMEX solvers, where each component of `f_stiff` depends only on the same
    component of y (a diagonal Jacobian; for eq. (5) the friction force, see
    `split_vector_field`). The diagonal d = d f_stiff / d y is one JVP with a
    tangent of ones, and every stage is one evaluation of f and one elementwise
    division by 1/(h gamma) - d. Only the stabilising part of d is used, min(d, 0):
    where friction falls with speed (d > 0, velocity weakening) the dynamics is not
    stiff, and W would otherwise become singular at h gamma d = 1. A W-method keeps
    its order for any W.

    **Arguments:**

    - `block`: an experimental W, block diagonal for a state of shape (..., 2, N)
        (x and x' of N oscillators): each oscillator's 2 x 2 block also holds
        dx/dt = x' and its own spring, dx''/dx = c (the sum over its row of the
        elastic Jacobian, min(c, 0), one JVP of `f_explicit` per solve), and each
        stage solves the blocks in closed form. On the Fig. 4 scene at eps = 1e-3
        it takes 7 % fewer steps (`docs/benchmarks/candidates/candidates.md`),
        but at eps <= 1e-4 its
        amplitude error on the single oscillator is 10 to 100 times the diagonal
        W's (0.4 % against 3e-4 at eps = 1e-4): not the default.

    The JVP at the step's end gives f(y1) and d(y1) together; they serve the next
    step as f(y0) and W (first same as last). Dense output is the cubic Hermite
    polynomial through y0, y1, f(y0), f(y1).

    The state must be an array (not a PyTree) and the system autonomous.
    """

    block: bool = eqx.field(static=True, default=False)
    term_structure: ClassVar = diffrax.MultiTerm[
        tuple[diffrax.AbstractTerm, diffrax.AbstractTerm]]
    interpolation_cls: ClassVar[Callable[..., diffrax.AbstractLocalInterpolation]] = (
        diffrax.ThirdOrderHermitePolynomialInterpolation.from_k)

    def order(self, terms):
        return 3

    def error_order(self, terms):
        return 3  # the embedded method has order 2, so its local error is O(h^3)

    def init(self, terms, t0, t1, y0, args):
        spring = _spring(terms, t0, y0, args) if self.block else None
        return (*_evaluate(terms, t0, y0, args), spring)

    def step(self, terms, t0, t1, y0: Float[Array, "*y"], args, solver_state,
             made_jump):
        del made_jump  # autonomous and smooth: f(y0) and d(y0) stay valid
        f0, d0, spring = solver_state
        h = t1 - t0
        scale = 1.0 / (h * _GAMMA) - jnp.minimum(d0, 0.0)
        solve = _diagonal_solve(scale) if spring is None else _block_solve(scale, spring)
        u = []
        for i in range(4):
            if i == 0:
                f = f0
            else:
                y_stage = y0 + sum(_A[i, j] * u[j] for j in range(i) if _A[i, j])
                f = _vector_field(terms, t0, y_stage, args)
            u.append(solve(f + sum(_C[i, j] / h * u[j] for j in range(i))))
        y1 = y0 + sum(_M[i] * u[i] for i in range(4))
        y_error = sum(_M_ERROR[i] * u[i] for i in range(4))
        f1, d1 = _evaluate(terms, t1, y1, args)
        dense_info = dict(y0=y0, y1=y1, k=jnp.stack([h * f0, h * f1]))
        return y1, y_error, dense_info, (f1, d1, spring), diffrax.RESULTS.successful

    def func(self, terms, t0, y0, args):
        return _vector_field(terms, t0, y0, args)


def _vector_field(terms, t, y, args):
    explicit, stiff = terms.terms
    return explicit.vf(t, y, args) + stiff.vf(t, y, args)


def _evaluate(terms, t, y: Float[ArrayLike, "*y"], args):
    """f(y) and the diagonal of the stiff term's Jacobian at y, from one JVP."""
    explicit, stiff = terms.terms
    f_stiff, d = jax.jvp(lambda z: stiff.vf(t, z, args), (y,), (jnp.ones_like(y),))
    return explicit.vf(t, y, args) + f_stiff, d


def _spring(terms, t, y, args):
    """The restoring part of each oscillator's own spring, min(dx''/dx summed over
    the row, 0), shape (..., N), for a state of shape (..., 2, N); else None."""
    if y.ndim < 2 or y.shape[-2] != 2:
        return None
    explicit = terms.terms[0]
    on_x = jnp.zeros_like(y).at[..., 0, :].set(1.0)
    _, jx = jax.jvp(lambda z: explicit.vf(t, z, args), (y,), (on_x,))
    return jnp.minimum(jx[..., 1, :], 0.0)


def _diagonal_solve(scale):
    """Solve diag(scale) u = r, as r times the reciprocal of `scale`, taken once per
    step: the four stages then multiply instead of divide, and XLA compiles a step
    loop about 1.4 times cheaper per step on the Fig. 4 scene (the same numbers to
    one rounding). (Dividing positions and velocities apart is cheaper still on
    this CPU, but under vmap with XLA's fast math it took 10-20 times the steps.)"""
    inverse = 1.0 / scale
    return lambda r: r * inverse


def _block_solve(scale, spring):
    """Solve, per oscillator, [[s_x, -1], [-c, s_v]] (u_x, u_v) = (r_x, r_v), with
    (s_x, s_v) = `scale` on the last two axes and c = `spring` <= 0, so that the
    determinant s_x s_v - c >= s_x s_v > 0."""
    s_x, s_v = scale[..., 0, :], scale[..., 1, :]
    det = s_x * s_v - spring

    def solve(r):
        r_x, r_v = r[..., 0, :], r[..., 1, :]
        return jnp.stack([(s_v * r_x + r_v) / det, (spring * r_x + s_x * r_v) / det],
                         axis=-2)

    return solve
