"""Harmonic balance: periodic orbits of eq. (5) in the frequency domain, the second
orbit method beside `Shooting`.

Each displacement is a truncated Fourier series in the phase tau = omega t,

    x_n(tau) = a_0n + sum_{k=1..H} (a_kn cos k tau + b_kn sin k tau),

and the unknowns are the coefficients (2H + 1 per oscillator) and the period T =
2 pi / omega. The residual is the Galerkin projection of eq. (5) onto the same
harmonics, by the alternating frequency-time scheme (Cameron and Griffin, J. Appl.
Mech. 56 (1989)): the series to M time samples of one period by the inverse FFT,
the model's acceleration there (its friction law smoothed, tanh(v_rel/eps), eq. (1)
with eq. (7)), and back by the FFT; M >= 4H + 1 keeps the products that the Hill
matrix needs free of aliasing. A phase condition x_n'(0) = 0 (as `Shooting`'s) fixes
the orbit's phase. Newton's method by optimistix, damped by backtracking where a
full step does not lower the residual; its linear steps by LU of the Jacobian
assembled from the field's (`HarmonicBalance.jacobian`: the friction's derivative is
diagonal over the oscillators) or by GMRES preconditioned by the Jacobian's
oscillator blocks (`BlockJacobiGMRES`).

Floquet multipliers from one monodromy integration over the period started on the
orbit, or by Hill's method (Lazarus and Thomas, C. R. Mecanique 338 (2010)
510-517): the variational equation with the ansatz e^{lambda t} q(t), q periodic in
the same harmonics, is an eigenvalue problem of size 2N (2H + 1); of its
eigenvalues, congruent modulo i omega, the 2N whose eigenvectors are most centred
on the harmonic 0 are the Floquet exponents, and mu = exp(lambda T).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Complex, Float, Int

from .._checks import check_count, check_positive, is_count
from .._engine.compat import checks_as_nan
from .._engine.engines import Smoothed
from .._errors import ValidationError
from .._physics.custom_types import State
from .._physics.forces import DEFAULT_EPS
from .._physics.model import split_vector_field
from .._physics.friction import as_parameter
from .._physics.params import ChainParams
from .harmonic_solve import BlockJacobiGMRES, CyclicBlockLU, couples_as_ring
from .orbit_method import (AbstractOrbitMethod, PeriodicOrbit, closing_condition,
                           damped_newton, deflated_multipliers, flow_direction, guess_period,
                           orbit_record, phased_guess)

#: How Floquet multipliers are computed: Hill's method, or one monodromy integration.
FLOQUET = ("hill", "monodromy")
#: How Newton's steps are solved: LU of the whole Jacobian, GMRES preconditioned by
#: its oscillator blocks (`BlockJacobiGMRES`), or block elimination over the
#: oscillators of a ring or a line (`CyclicBlockLU`).
LINEAR_SOLVERS = ("lu", "blocks", "ring")


class JacobianBlocks(NamedTuple):
    """A harmonic-balance Jacobian (`HarmonicBalance.jacobian_blocks`) by its
    oscillator blocks, m = 2H + 1 coefficients each:

    - `own`: oscillator n's block, shape (n_osc, m, m): its inertia, stiffness,
        damping and friction (dense in the harmonics);
    - `stiffness`, `damping`: the blocks P S and omega P S' of a displacement's and
        a velocity's term, shape (m, m): oscillator i's block of j != i is
        -(stiffness E_x[i, j] + damping E_v[i, j]);
    - `linear`: the field's linear Jacobian E, shape (2 n_osc, 2 n_osc);
    - `period_column`, `closing_row`: the period's column and the closing
        condition's row of the whole Jacobian, shape (n_osc m + 1,).
    """

    own: Float[Array, "n m m"]
    stiffness: Float[Array, "m m"]
    damping: Float[Array, "m m"]
    linear: Float[Array, "2n 2n"]
    period_column: Float[Array, " size"]
    closing_row: Float[Array, " size"]


class HarmonicBalance(AbstractOrbitMethod):
    """Harmonic balance with the alternating frequency-time scheme (this module's
    docstring): periodic orbits of the smoothed model as truncated Fourier series.

    **Arguments:**

    - `eps`: the smoothing velocity of the friction law tanh(v_rel/eps) (> 0,
        dimensionless), 1e-3 by default: harmonic balance needs a smooth law. An
        array leaf: a new eps does not recompile, and results are differentiable
        in it.
    - `harmonics`: H, the highest harmonic kept (>= 1). A stick-slip orbit has a
        kink in its velocity, so its coefficients fall slowly: check the result
        against a larger H.
    - `time_samples`: M, time samples of one period in the alternating frequency-time
        scheme (>= 4H + 1); by default the smallest power of two that is.
    - `floquet`: how the Floquet multipliers are computed: "monodromy" (default:
        one integration over the period from the orbit's start, by the smoothed
        engine made `for_orbits`, differentiated in forward mode) or "hill" (Hill's
        method: an eigenvalue problem of size 2 n_osc (2H + 1), whose cost grows as
        its cube; on the single oscillator at H = 64 it costs 40 times the
        integration and needs H = 64 where the orbit needs 32).
    - `newton_tol`, `newton_steps`: the tolerance (optimistix, rtol = atol) and the
        iteration budget of Newton's method damped by backtracking (`solve`).
    - `n_samples`: samples of one period from which amplitudes and stick are read.
    - `phase_oscillator`: the oscillator n of the phase condition x_n'(0) = 0.
    - `linear_solver`: how each Newton step's linear system is solved: "blocks"
        (default: GMRES preconditioned by the Jacobian's oscillator blocks, of size
        2H + 2, `BlockJacobiGMRES`: the friction Jacobian is block diagonal over the
        oscillators; LU on one oscillator, whose one block is the whole Jacobian) or
        "lu" (LU of the whole Jacobian, of size n_osc (2H + 1) + 1) or "ring"
        (direct block elimination over the oscillators, `CyclicBlockLU`, for a
        ring or a line: exact, about n_osc^2 / 15 times less arithmetic than LU;
        another structure is refused with `ValidationError` when solved).

    The unknowns u: the coefficients, shape (2H + 1, n_osc) flattened (rows a_0,
    a_1..a_H, b_1..b_H), then T.

    **Raises:**

    `ValidationError` naming the field for eps <= 0, H < 1, M < 4H + 1, an unknown
    `floquet` or `linear_solver`, a non-positive tolerance or count, or a negative
    phase oscillator.
    """

    eps: ArrayLike = eqx.field(converter=as_parameter)
    harmonics: int = eqx.field(static=True)
    time_samples: int = eqx.field(static=True)
    floquet: str = eqx.field(static=True)
    newton_tol: float = eqx.field(static=True)
    newton_steps: int = eqx.field(static=True)
    n_samples: int = eqx.field(static=True)
    phase_oscillator: int = eqx.field(static=True)
    linear_solver: str = eqx.field(static=True)

    def __init__(self, eps=DEFAULT_EPS, harmonics: int = 32, time_samples: int | None = None, *,
                 floquet: str = "monodromy", newton_tol: float = 1e-9, newton_steps: int = 40,
                 n_samples: int = 4096, phase_oscillator: int = 0,
                 linear_solver: str = "blocks"):
        self.eps = eps
        self.harmonics = harmonics
        self.time_samples = (int(2 ** np.ceil(np.log2(4 * harmonics + 1)))
                             if time_samples is None and is_count(harmonics)
                             and harmonics >= 1 else time_samples)
        self.floquet = floquet
        self.newton_tol = newton_tol
        self.newton_steps = newton_steps
        self.n_samples = n_samples
        self.phase_oscillator = phase_oscillator
        self.linear_solver = linear_solver

    def __check_init__(self):
        check_count("HarmonicBalance.harmonics", self.harmonics)
        check_count("HarmonicBalance.time_samples", self.time_samples, 4 * self.harmonics + 1)
        check_count("HarmonicBalance.n_samples", self.n_samples, 2 * self.harmonics + 1)
        check_count("HarmonicBalance.newton_steps", self.newton_steps)
        check_count("HarmonicBalance.phase_oscillator", self.phase_oscillator, 0)
        check_positive("HarmonicBalance.newton_tol", self.newton_tol)
        if self.linear_solver not in LINEAR_SOLVERS:
            raise ValidationError(f"HarmonicBalance.linear_solver must be one of "
                                  f"{LINEAR_SOLVERS}, got {self.linear_solver!r}")
        if self.floquet not in FLOQUET:
            raise ValidationError(f"HarmonicBalance.floquet must be one of {FLOQUET}, got "
                                  f"{self.floquet!r}")
        # eps: checked by the smoothed engine that holds the law
        Smoothed(eps=self.eps)

    @property
    def engine(self) -> Smoothed:
        """The smoothed model at this eps, integrated as orbits need it: its
        acceleration is the residual's, its flow gives the guess's samples and the
        monodromy check."""
        return Smoothed(eps=self.eps).for_orbits()

    # --- the unknowns ---

    def unknowns(self, params: ChainParams, y0: State, period) -> Float[Array, " n"]:
        """The coefficients of the smoothed model's orbit through the guess: one period
        integrated from y0 (the phase oscillator's velocity set to 0), sampled at the
        M times of the scheme and projected onto the harmonics.

        **Raises:** `ValidationError` for a guess of the wrong shape or a phase
        oscillator outside the chain."""
        return self._projected(params, phased_guess(self, params, y0),
                               guess_period(params, period))

    def start(self, orbit: PeriodicOrbit) -> Float[Array, " n"]:
        """The unknowns of the converged `orbit` (of any method): projected from its
        state and period (`unknowns`), then solved by Newton's method."""
        u, _ = self.solve(orbit.params, self.unknowns(orbit.params, orbit.y0, orbit.period))
        return u

    def solve(self, params: ChainParams, u0: Float[Array, " n"]
              ) -> tuple[Float[Array, " n"], Bool[Array, ""]]:
        """Newton's method damped by backtracking (`damped_newton`): full steps near
        the orbit, short ones from a guess far from it (a forced response from rest
        at resonance, where the friction force's jumps make full steps overshoot).
        Traceable (`jax.vmap` over chains), differentiable by the implicit function
        theorem."""
        return _solve(self, params, u0)

    def orbit(self, u: Float[Array, " n"]) -> tuple[State, Float[Array, ""]]:
        coefficients, period = self._split(u)
        x, dx = self._series(coefficients, 1)
        omega = 2 * jnp.pi / period
        return jnp.stack([x[0], omega * dx[0]]), period

    def _split(self, u):
        return jnp.reshape(u[:-1], (2 * self.harmonics + 1, -1)), u[-1]

    def _spectrum(self, coefficients) -> Complex[Array, "h n"]:
        """Z_k with x = sum_{|k| <= H} Z_k e^{i k tau}, Z_{-k} = conj Z_k: k = 0..H."""
        h = self.harmonics
        a0, a, b = coefficients[0], coefficients[1:h + 1], coefficients[h + 1:]
        return jnp.concatenate([a0[None].astype(complex), 0.5 * (a - 1j * b)])

    def _series(self, coefficients, order: int, m: int | None = None) -> list:
        """x and its first `order` derivatives in tau at m equally spaced phases
        (M by default), each shape (m, n_osc): the inverse FFT."""
        m = self.time_samples if m is None else m
        z = self._spectrum(coefficients)
        k = jnp.arange(self.harmonics + 1)[:, None]
        return [jnp.fft.irfft(m * z * (1j * k) ** p, n=m, axis=0) for p in range(order + 1)]

    def _projection(self, r: Float[Array, "m n"]) -> Float[Array, "2h+1 n"]:
        """The coefficients a_0, a_k, b_k of the samples r over one period (the FFT),
        up to H."""
        spectrum = jnp.fft.rfft(r, axis=0)[:self.harmonics + 1] / r.shape[0]
        return jnp.concatenate([spectrum[:1].real, 2 * spectrum[1:].real,
                                -2 * spectrum[1:].imag])

    def _projected(self, params, y0, period):
        """The unknowns of the smoothed model's trajectory from y0 over one period."""
        m = self.time_samples
        ts = period * jnp.arange(1, m + 1) / m
        ys = self.engine.flow(params, y0, ts)
        xs = jnp.concatenate([y0[None, 0], ys[:-1, 0]])
        return jnp.concatenate([jnp.ravel(self._projection(xs)), jnp.atleast_1d(period)])

    # --- the residual ---

    def _states(self, coefficients, period, m: int | None = None) -> Float[Array, "m 2 n"]:
        x, dx = self._series(coefficients, 1, m)
        return jnp.stack([x, 2 * jnp.pi / period * dx], axis=1)

    def residual(self, u: Float[Array, " n"], params: ChainParams) -> Float[Array, " n"]:
        """The harmonics of x'' minus the model's acceleration (the alternating
        frequency-time scheme; a forcing's at the samples' times), shape
        (2H + 1) n_osc, and the phase condition sum_k k b_kn (x_n'(0) / omega, n the
        phase oscillator; for a forced chain the force's period,
        `closing_condition`). Where Newton's steps are solved by LU, its derivative
        in u is `jacobian`, assembled from the field's Jacobian at the samples."""
        if self._assembled(params):
            return _assembled_residual(self, u, params)
        return self._balance(u, params)

    def _assembled(self, params: ChainParams) -> bool:
        # GMRES's products need no matrix: there, the residual's own derivative
        return self.linear_solver in ("lu", "ring") or params.n_osc == 1

    def jacobian(self, u: Float[Array, " n"], params: ChainParams) -> Float[Array, "n n"]:
        """The Jacobian of `residual` in u, shape (n, n), n = n_osc (2H + 1) + 1,
        assembled from its oscillator blocks (`jacobian_blocks`) rather than
        differentiated through the FFTs."""
        blocks = self.jacobian_blocks(u, params)
        n = blocks.own.shape[0]
        eye = jnp.eye(n)
        off = 1.0 - eye
        block = (jnp.einsum("irl,ij->rilj", blocks.own, eye)
                 - jnp.einsum("rl,ij->rilj", blocks.stiffness, off * blocks.linear[n:, :n])
                 - jnp.einsum("rl,ij->rilj", blocks.damping, off * blocks.linear[n:, n:]))
        size = u.shape[0]
        return (jnp.zeros((size, size)).at[:-1, :-1].set(jnp.reshape(block, (size - 1,) * 2))
                .at[:, -1].set(blocks.period_column).at[-1, :].set(blocks.closing_row))

    def jacobian_blocks(self, u: Float[Array, " n"], params: ChainParams) -> JacobianBlocks:
        """The Jacobian of `residual` in u by its oscillator blocks (`JacobianBlocks`).
        Eq. (5)'s field is a linear part (springs, coupling, viscous damping,
        masses: one constant Jacobian E) plus the friction force, whose oscillator n
        depends on its own velocity only (`split_vector_field`): one derivative
        d_n(t) per oscillator and sample. The coefficients' block is then the
        Galerkin projection of the linearised equation (this module's docstring),

            omega^2 (P S'') I - (P S) E_x - omega (P S') E_v
              - omega diag_n(sum_t P_t d_n(t) S'_t),

        with S, S', S'' the series and its derivatives in the phase at the M
        samples and P the projection back onto the harmonics: the friction term is
        block diagonal over the oscillators, the linear part diagonal in the
        harmonics but for the rotation P S'. The period's column by one
        forward-mode product, the closing row by one reverse-mode one."""
        coefficients, period = self._split(u)
        omega = 2 * jnp.pi / period
        n = coefficients.shape[1]
        series, slope, curvature, projection = (jnp.asarray(b) for b in _bases(
            self.harmonics, self.time_samples))
        linear = jax.jacfwd(lambda y: jnp.ravel(split_vector_field(
            0.0, jnp.reshape(y, (2, n)), params, self.eps)[0]))(jnp.zeros(2 * n))
        x, dx = self._series(coefficients, 1)

        def friction_slope(x, v):  # d(friction acceleration)_n / d v_n, shape (n,)
            return jax.jvp(lambda w: split_vector_field(0.0, jnp.stack([x, w]), params,
                                                        self.eps)[1][1], (v,), (jnp.ones(n),))[1]

        slopes = jax.vmap(friction_slope)(x, omega * dx)  # (M, n)
        stiffness, damping = projection @ series, omega * (projection @ slope)
        own = (omega**2 * (projection @ curvature)[None]
               - stiffness[None] * jnp.diag(linear[n:, :n])[:, None, None]
               - damping[None] * jnp.diag(linear[n:, n:])[:, None, None]
               - omega * jnp.einsum("rt,tl,ti->irl", projection, slope, slopes))
        size = u.shape[0]
        period_column = jax.jvp(lambda v: self._balance(v, params), (u,),
                                (jnp.zeros(size).at[-1].set(1.0),))[1]
        closing_row = jax.grad(lambda v: self._balance(v, params)[-1])(u)
        return JacobianBlocks(own, stiffness, damping, linear, period_column, closing_row)

    def _balance(self, u: Float[Array, " n"], params: ChainParams) -> Float[Array, " n"]:
        coefficients, period = self._split(u)
        omega = 2 * jnp.pi / period
        x, dx, ddx = self._series(coefficients, 2)
        ys = jnp.stack([x, omega * dx], axis=1)
        ts = period * jnp.arange(self.time_samples) / self.time_samples
        accel = jax.vmap(lambda y, t: self.engine.field(params, y, t)[1])(ys, ts)
        balance = self._projection(omega**2 * ddx - accel)
        h, n = self.harmonics, self.phase_oscillator
        phase = jnp.sum(jnp.arange(1, h + 1) * coefficients[h + 1:, n])
        return jnp.concatenate([jnp.ravel(balance), closing_condition(params, phase, period)])

    # --- the orbit described ---

    def samples(self, params: ChainParams, u: Float[Array, " n"], ts) -> Array:
        coefficients, period = self._split(u)
        h = self.harmonics
        tau = 2 * jnp.pi / period * jnp.asarray(ts)[:, None]
        k = jnp.arange(1, h + 1)
        a, b = coefficients[1:h + 1], coefficients[h + 1:]
        cos, sin = jnp.cos(tau * k), jnp.sin(tau * k)
        x = coefficients[0] + cos @ a + sin @ b
        v = (2 * jnp.pi / period) * (-(sin * k) @ a + (cos * k) @ b)
        return jnp.stack([x, v], axis=1)

    def _jacobians(self, params, u) -> Float[Array, "m 2n 2n"]:
        """The Jacobian of the model's field at the M samples of the orbit."""
        coefficients, period = self._split(u)
        ys = self._states(coefficients, period)
        shape = ys.shape[1:]
        return jax.vmap(jax.jacfwd(
            lambda y: jnp.ravel(self.engine.field(params, jnp.reshape(y, shape)))))(
                jnp.reshape(ys, (ys.shape[0], -1)))

    def hill_exponents(self, params: ChainParams, u: Float[Array, " n"]
                       ) -> tuple[Complex[Array, " 2n"], Complex[Array, "2n 2n"]]:
        """(The 2 n_osc Floquet exponents lambda by Hill's method; their eigenvectors'
        values at t = 0, as columns), this module's docstring."""
        _, period = self._split(u)
        omega = 2 * jnp.pi / period
        jac = self._jacobians(params, u)
        m, d = jac.shape[0], jac.shape[1]
        h = self.harmonics
        fourier = jnp.fft.fft(jac, axis=0) / m  # J_k at k mod M
        k = jnp.arange(-h, h + 1)
        blocks = fourier[(k[:, None] - k[None, :]) % m]  # (2h+1, 2h+1, d, d)
        hill = jnp.reshape(jnp.transpose(blocks, (0, 2, 1, 3)), ((2 * h + 1) * d,) * 2)
        hill = hill - jnp.diag(jnp.repeat(1j * omega * k, d))
        # in the real basis (cos, sin) the same operator is a real matrix: a real
        # eigenvalue problem, several times cheaper than the complex one
        to_real = jnp.asarray(_real_basis(h, d))
        real = jnp.real(to_real @ hill @ jnp.conj(to_real).T)
        values, vectors = jnp.linalg.eig(real)
        q = jnp.reshape((jnp.conj(to_real).T @ vectors).T, (-1, 2 * h + 1, d))
        weight = jnp.sum(jnp.abs(q) ** 2, axis=2)  # eigenvector, harmonic -H..H
        centre = jnp.abs(weight @ k / jnp.sum(weight, axis=1))
        keep = jnp.argsort(centre)[:d]
        return values[keep], jnp.sum(q[keep], axis=1).T

    def monodromy(self, params: ChainParams, u: Float[Array, " n"]) -> Float[Array, "2n 2n"]:
        """The monodromy matrix of the orbit u: by Hill's method (V exp(Lambda T) V^-1
        from its Floquet exponents and their eigenvectors at t = 0), or by one
        integration over the period (`floquet="monodromy"`)."""
        y0, period = self.orbit(u)
        if self.floquet == "monodromy":
            shape = y0.shape
            return jax.jacfwd(lambda y: jnp.ravel(self.engine.flow(
                params, jnp.reshape(y, shape), period)))(jnp.ravel(y0))
        exponents, vectors = self.hill_exponents(params, u)
        return jnp.real(vectors @ jnp.diag(jnp.exp(exponents * period))
                        @ jnp.linalg.inv(vectors))

    def multipliers(self, params: ChainParams, u: Float[Array, " n"]
                    ) -> tuple[Complex[Array, " 2n"], Int[Array, ""]]:
        y0, _ = self.orbit(u)
        return deflated_multipliers(self.monodromy(params, u),
                                    flow_direction(self.engine, params, y0))

    def describe(self, u: Float[Array, " n"], params: ChainParams) -> PeriodicOrbit:
        coefficients, period = self._split(u)
        y0, _ = self.orbit(u)
        ys = self._states(coefficients, period, self.n_samples)
        # Liouville: det M = exp(integral of the field's divergence over the period)
        trace = jnp.trace(self._jacobians(params, u), axis1=1, axis2=2)
        residual = jnp.max(jnp.abs(self.residual(u, params)))
        return orbit_record(params, y0, period, ys, self.engine.on_halc(params, ys),
                            self.monodromy(params, u), flow_direction(self.engine, params, y0),
                            self.newton_tol, period * jnp.mean(trace), residual,
                            residual <= 1e3 * self.newton_tol)

    def with_phase_oscillator(self, n: int) -> HarmonicBalance:
        return dataclasses.replace(self, phase_oscillator=n)


@checks_as_nan
@eqx.filter_jit
def _solve(method: HarmonicBalance, params: ChainParams, u0):
    # one oscillator: its one block is the whole Jacobian
    linear_solver = lx.LU()
    if method.linear_solver == "blocks" and params.n_osc > 1:
        linear_solver = BlockJacobiGMRES(method.harmonics, params.n_osc,
                                         method.phase_oscillator)
    elif method.linear_solver == "ring" and params.n_osc > 1:
        if not couples_as_ring(params):
            raise ValidationError("HarmonicBalance.linear_solver 'ring' needs a ring or a "
                                  "line of oscillators; this chain's graph couples others: "
                                  "use 'blocks' or 'lu'")
        # the derivatives' system (`damped_newton`) couples oscillators further
        return damped_newton(method, params, u0, method.newton_steps,
                             CyclicBlockLU(method.harmonics, params.n_osc), lx.LU())
    return damped_newton(method, params, u0, method.newton_steps, linear_solver)


@eqx.filter_custom_jvp
def _assembled_residual(method: HarmonicBalance, u, params: ChainParams):
    return method._balance(u, params)


@_assembled_residual.def_jvp
def _assembled_residual_jvp(primals, tangents):
    """The residual's derivative in u by its assembled `jacobian`, in the method's
    and the chain's parameters by their Jacobians (forward mode through the
    residual, one pass per element of each moved parameter: a few), each then
    applied to the tangent: one matrix for all the directions that LU's
    materialisation asks for (a continued parameter's column among them)."""
    method, u, params = primals
    t_method, t_u, t_params = tangents
    r = method._balance(u, params)
    t_r = jnp.zeros_like(r)
    if t_u is not None:
        t_r = t_r + method.jacobian(u, params) @ t_u
    leaves, structure = jax.tree_util.tree_flatten((method, params))
    t_leaves = structure.flatten_up_to((t_method, t_params))
    for i, t in enumerate(t_leaves):
        if t is None:
            continue

        def balance(value, i=i):
            changed = list(leaves)
            changed[i] = value
            m, p = jax.tree_util.tree_unflatten(structure, changed)
            return m._balance(u, p)

        leaf = jnp.asarray(leaves[i])
        column = jax.jacfwd(balance)(leaf)  # (n,) + the leaf's shape
        t_r = t_r + jnp.tensordot(column, t, axes=leaf.ndim)
    return r, t_r


def _bases(h: int, m: int) -> tuple[np.ndarray, ...]:
    """The series (1, cos k tau, sin k tau) at the M phases tau_t = 2 pi t / M, shape
    (M, 2H + 1), its first and second derivatives in tau, and the projection back
    onto the coefficients (the FFT's, `HarmonicBalance._projection`), shape
    (2H + 1, M)."""
    tau = 2 * np.pi * np.arange(m)[:, None] / m
    k = np.arange(1, h + 1)[None]
    cos, sin = np.cos(k * tau), np.sin(k * tau)
    one, zero = np.ones((m, 1)), np.zeros((m, 1))
    series = np.hstack([one, cos, sin])
    slope = np.hstack([zero, -k * sin, k * cos])
    curvature = np.hstack([zero, -k**2 * cos, -k**2 * sin])
    projection = np.vstack([one.T / m, 2 * cos.T / m, 2 * sin.T / m])
    return series, slope, curvature, projection


def _real_basis(h: int, d: int) -> np.ndarray:
    """The unitary map from the coefficients q_k, k = -h..h (each of d components),
    of a series sum_k q_k e^{i k tau} to (c_0, c_1, s_1, ..., c_h, s_h) scaled to
    keep norms: c_k = (q_k + q_-k) / sqrt 2, s_k = i (q_k - q_-k) / sqrt 2, c_0 = q_0,
    shape ((2h + 1) d, (2h + 1) d). A real series has real (c, s)."""
    t = np.zeros((2 * h + 1, 2 * h + 1), dtype=complex)
    t[0, h] = 1.0
    for k in range(1, h + 1):
        t[2 * k - 1, h + k] = t[2 * k - 1, h - k] = 1 / np.sqrt(2)
        t[2 * k, h + k], t[2 * k, h - k] = 1j / np.sqrt(2), -1j / np.sqrt(2)
    return np.kron(t, np.eye(d))
