"""Stability of steady sliding and its Hopf boundary: mode by mode on the paper's
homogeneous ring (the Fourier route), from the eigenvalues of the Jacobian for any
chain."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Complex, Float

from .._engine.compat import checks_as_nan
from .._engine.checks import check_params, real_array
from .._engine.engines import AbstractEngine, Smoothed
from .._physics.forces import friction_coefficient
from .._physics.friction import ExponentialDecay
from .._physics.params import is_homogeneous_ring
from .._physics.params import ChainParams, with_parameter
from .._errors import ValidationError
from .._printing import values_repr


def _require_ring(params: ChainParams, what: str) -> None:
    if not is_homogeneous_ring(params):
        raise ValidationError(f"{what} needs the homogeneous ring (boundary 'ring', scalar "
                              "per-oscillator fields); use steady_sliding_eigenvalues for "
                              "any chain")


def check_engine(engine, owner: str = "engine") -> AbstractEngine:
    """`engine` at its settings for orbits (`AbstractEngine.for_orbits`), which are
    the same for every eps: the analyses of steady sliding read the engine's model
    only (its `jacobian` at steady sliding), so that a new eps, an array leaf traced
    by `eqx.filter_jit`, does not recompile them, and derivatives with respect to
    it flow.

    **Raises:** `TypeError` naming `owner` for a value that is not an engine."""
    if not isinstance(engine, AbstractEngine):
        raise TypeError(f"{owner} must be an engine (jaxchain.Smoothed or jaxchain.Exact), "
                        f"got {type(engine).__name__}")
    return engine.for_orbits()


def _fourier_blocks(params: ChainParams, engine: AbstractEngine
                    ) -> Complex[Array, "n_osc 2 2"]:
    """The Jacobian of eq. (5) at steady sliding (`jacobian` at steady sliding of the
    engine, by `jax.jacfwd`),
    block-diagonalised by the discrete Fourier transform of the ring.

    The Jacobian is block-circulant (every oscillator sees the same law, the ring
    is periodic), so each Fourier mode k, x_n ~ exp(2 pi i k n / N), evolves on its
    own with the 2x2 block E_k^H J E_k,

        [[0, 1], [-(1 + 4 eta_c sin^2(pi k / N)), F'(-v_d) - 2 xi]].

    The union of the blocks' eigenvalues is the spectrum of J.

    **Arguments:**

    - `params`: the chain parameters.
    - `engine`: the engine whose model is linearised.

    **Returns:**

    Blocks of shape (n_osc, 2, 2), complex, for k = 0..N-1 (k = 0 in phase,
    k = N/2 anti-phase).

    **Raises:**

    `ValidationError` unless the chain is the homogeneous ring.
    """
    _require_ring(params, "fourier_blocks")
    n = params.n_osc
    jac = jnp.reshape(engine.jacobian(params), (2, n, 2, n))
    k, m = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    modes = jnp.asarray(np.exp(2j * np.pi * k * m / n) / np.sqrt(n))  # (k, m)
    return jnp.einsum("km,imjl,kl->kij", modes.conj(), jac, modes)


def mode_eigenvalues(params: ChainParams, engine: AbstractEngine = Smoothed()
                     ) -> Complex[Array, "n_osc 2"]:
    """Eigenvalues of each Fourier block of the Jacobian at steady sliding, in
    closed form (lambda = tr/2 +- sqrt(tr^2/4 - det)), so that they are smooth in
    the parameters and JAX differentiates them exactly.

    **Arguments:**

    - `params`: the chain parameters (the homogeneous ring).
    - `engine`: the engine whose model is linearised (`AbstractEngine`):
        `Smoothed()` (eps = 1e-3) by default; the smoothing velocity is its
        `Smoothed.eps`, an array leaf (a new value does not recompile, and
        derivatives with respect to it flow); `Exact()` gives the limit eps -> 0.

    **Returns:**

    Shape (n_osc, 2), complex, the larger real part first.

    **Raises:**

    `ValidationError` unless the chain is the homogeneous ring.
    """
    return _mode_eigenvalues(params, check_engine(engine))


@eqx.filter_jit
def _mode_eigenvalues(params: ChainParams, engine) -> Complex[Array, "n_osc 2"]:
    """`mode_eigenvalues` as one compiled program (not op by op)."""
    blocks = _fourier_blocks(params, engine)
    half_trace = 0.5 * (blocks[:, 0, 0] + blocks[:, 1, 1])
    det = blocks[:, 0, 0] * blocks[:, 1, 1] - blocks[:, 0, 1] * blocks[:, 1, 0]
    root = jnp.sqrt(half_trace**2 - det)
    root = jnp.where(root.real >= 0, root, -root)
    return jnp.stack([half_trace + root, half_trace - root], axis=-1)


def steady_sliding_eigenvalues(params: ChainParams, engine: AbstractEngine = Smoothed()
                               ) -> Complex[Array, " 2n_osc"]:
    """The eigenvalues of the Jacobian of eq. (5) at steady sliding, for any chain:
    by the Fourier route (`mode_eigenvalues`) on the homogeneous ring, by
    `jnp.linalg.eigvals` of the Jacobian (the engine's `jacobian` at steady sliding,
    by `jax.jacfwd`) otherwise.

    **Arguments:**

    - `params`: the chain parameters.
    - `engine`: the engine whose model is linearised (`AbstractEngine`):
        `Smoothed()` (eps = 1e-3) by default; the smoothing velocity is its
        `Smoothed.eps`, an array leaf (a new value does not recompile, and
        derivatives with respect to it flow); `Exact()` gives the limit eps -> 0.
        Steady sliding is the fixed point of the engine's model.

    **Returns:**

    Shape (2 n_osc,), complex, sorted by decreasing real part (then imaginary
    part), dimensionless (per unit of time, eq. (4)).
    """
    return _steady_sliding_eigenvalues(params, check_engine(engine))


@eqx.filter_jit
def _steady_sliding_eigenvalues(params: ChainParams, engine) -> Complex[Array, " 2n_osc"]:
    """`steady_sliding_eigenvalues` as one compiled program (not op by op)."""
    if is_homogeneous_ring(params):
        values = jnp.reshape(_mode_eigenvalues(params, engine), (-1,))
    else:
        values = jnp.linalg.eigvals(engine.jacobian(params))
    order = jnp.lexsort((-values.imag, -values.real))
    return values[order]


def leading_growth_rate(params: ChainParams, engine: AbstractEngine = Smoothed()
                        ) -> Float[Array, ""]:
    """max Re(lambda) over the eigenvalues of the Jacobian at steady sliding
    (`steady_sliding_eigenvalues` of `engine`'s model, `Smoothed()` by default):
    steady sliding is stable where it is negative. Dimensionless (per unit of
    time, eq. (4))."""
    return jnp.max(steady_sliding_eigenvalues(params, engine).real)


def growth_rates(params: ChainParams, engine: AbstractEngine = Smoothed()
                 ) -> Float[Array, " modes"]:
    """Growth rates about steady sliding; steady sliding is stable when all are
    negative.

    **Arguments:**

    - `params`: the chain parameters.
    - `engine`: the engine whose model is linearised (`AbstractEngine`):
        `Smoothed()` (eps = 1e-3) by default; the smoothing velocity is its
        `Smoothed.eps`, an array leaf (a new value does not recompile, and
        derivatives with respect to it flow); `Exact()` gives the limit eps -> 0.

    **Returns:**

    On the homogeneous ring, max Re(lambda) of each Fourier mode, shape (n_osc,);
    on any other chain, Re(lambda) of every eigenvalue of the Jacobian, shape
    (2 n_osc,), decreasing. Dimensionless (per unit of time, eq. (4)).
    """
    if is_homogeneous_ring(params):
        return mode_eigenvalues(params, engine)[:, 0].real
    return steady_sliding_eigenvalues(params, engine).real


def hopf_vd_analytic(params: ChainParams) -> Float[Array, ""]:
    """The Hopf belt speed of steady sliding for sign() friction (eps -> 0):
    the effective damping 2 xi - mu'(v_d) vanishes at

        v_d,H = v0 ln((mu_st - mu_d) / (2 xi v0)),

    the same for every Fourier mode (the coupling is conservative, the damping
    uniform). 0.5 ln(10) = 1.1513 for eq. (7) of the paper (shared/DESIGN.md).

    For another friction law or a chain whose damping differs between
    oscillators, use `hopf_point` (root finding on the Jacobian's eigenvalues).

    **Raises:**

    `ValidationError` if xi = 0 or mu_st = mu_d (no Hopf point), or if the law is not
    eq. (1) or the load and damping are not uniform.
    """
    law = params.friction
    if not isinstance(law, ExponentialDecay):
        raise ValidationError(f"hopf_vd_analytic is the closed form of eq. (1) "
                              f"(ExponentialDecay), got {type(law).__name__}; use hopf_point")
    if any(np.ndim(a) for a in (params.xi, params.load, law.mu_st, law.mu_d, law.v0)):
        raise ValidationError("hopf_vd_analytic needs uniform xi, load and friction law; "
                              "use hopf_point")
    xi, delta = np.asarray(params.xi), np.asarray(law.mu_st) - np.asarray(law.mu_d)
    if np.any(xi <= 0) or np.any(delta <= 0):
        raise ValidationError(f"hopf_vd_analytic needs xi > 0 and mu_st > mu_d, got xi = "
                              f"{params.xi!r}, mu_st - mu_d = {delta!r}")
    return law.v0 * jnp.log(params.load * (law.mu_st - law.mu_d) / (2 * params.xi * law.v0))


def hopf_eps_correction(params: ChainParams, engine: AbstractEngine = Smoothed()
                        ) -> Float[Array, ""]:
    """Leading-order shift of the Hopf belt speed by the tanh smoothing,

        v_d,H(eps) - v_d,H(0) = -v0 (2 + 2 mu(v_d,H) / (xi eps)) exp(-2 v_d,H / eps),

    from expanding tanh(v/eps) = 1 - 2 exp(-2v/eps) and sech^2(v/eps) = 4
    exp(-2v/eps) in F'(-v_d) = 2 xi. Exponentially small: 1e-1000 at eps = 1e-3, and
    -5.6e-4 at eps = 0.2 for eq. (7).

    **Arguments:**

    - `params`: the chain parameters (as `hopf_vd_analytic` takes them).
    - `engine`: the smoothed engine whose smoothing velocity eps
        (`Smoothed.eps`) shifts the Hopf point; `Smoothed()` (eps = 1e-3) by
        default. Differentiable in its eps.

    **Returns:**

    The shift, shape (), dimensionless (always negative).

    **Raises:**

    As `hopf_vd_analytic`; `ValidationError` for an engine that smooths nothing
    (`AbstractEngine.as_smoothed`).
    """
    eps = engine.as_smoothed("hopf_eps_correction").eps
    v = hopf_vd_analytic(params)
    mu = params.load * friction_coefficient(params, v)
    return -params.friction.v0 * (2 + 2 * mu / (params.xi * eps)) * jnp.exp(-2 * v / eps)


class HopfPoint(eqx.Module):
    """The Hopf boundary of steady sliding.

    **Fields:**

    - `v_d`: the Hopf belt speed of every Fourier mode, shape (n_osc,) on the
        homogeneous ring; shape (1,) (the leading eigenvalue) on any other chain.
        Steady sliding is stable above the largest.
    - `omega`: angular frequency of each mode at its Hopf point, shape (n_osc,).
    - `slope`: d Re(lambda) / d v_d of each mode at its Hopf point, by JAX, shape
        (n_osc,); negative (the speed stabilises steady sliding). On a chain other
        than the homogeneous ring a diagnostic that JAX holds constant: its
        derivative would need the derivatives of non-symmetric eigenvectors.
    - `residual`: growth rate at the returned v_d, shape (n_osc,).
    - `newton_steps`: Newton iterations of each mode, shape (n_osc,).

    `v_d`, `omega` and `residual` are differentiable in every parameter of the
    chain (`hopf_point`).
    """

    v_d: Float[Array, " n_osc"]
    omega: Float[Array, " n_osc"]
    slope: Float[Array, " n_osc"]
    residual: Float[Array, " n_osc"]
    newton_steps: Array

    __repr__ = values_repr


def _mode_growth(v_d, args):
    params, engine, k = args
    return _mode_eigenvalues(with_parameter(params, "v_d", v_d), engine)[k, 0].real


@checks_as_nan
@eqx.filter_jit
def _hopf_modes(params: ChainParams, engine, guess, rtol, atol):
    solver = optx.Newton(rtol=rtol, atol=atol)

    def one(k):
        sol = optx.root_find(_mode_growth, solver, guess, (params, engine, k), max_steps=100,
                             throw=False)
        at = with_parameter(params, "v_d", sol.value)
        slope = jax.grad(_mode_growth)(sol.value, (params, engine, k))
        return (sol.value, jnp.abs(_mode_eigenvalues(at, engine)[k, 0].imag), slope,
                _mode_eigenvalues(at, engine)[k, 0].real, sol.stats["num_steps"],
                sol.result)

    return jax.vmap(one)(jnp.arange(params.n_osc))


def critical_mode(params: ChainParams, mode: int = 0, engine: AbstractEngine = Smoothed()):
    """The critical mode at a Hopf point (`params.v_d` at it): its frequency omega,
    the right eigenvector q of the Jacobian (A q = i omega q, |q| = 1) and the left
    one p (A^T p = -i omega p, <p, q> = conj(p) . q = 1), as the normal form of the
    Hopf bifurcation takes them (Kuznetsov, *Elements of Applied Bifurcation
    Theory*, Sect. 3.5).

    On the homogeneous ring, Fourier mode `mode` (0 in phase or N/2 anti-phase, a
    real mode shape), from its 2x2 block (`_fourier_blocks`); on any other chain the
    eigenvalue of the Jacobian with the largest real part and positive imaginary
    part (`mode` must be 0). The Jacobian is that of `engine`'s model
    (`jacobian` at steady sliding; `Smoothed()` by default, smoothed at its eps).

    **Returns:**

    (omega, q, p): shape (), (2 n_osc,) and (2 n_osc,) complex.

    **Raises:**

    `ValidationError` for a bad mode.
    """
    n = params.n_osc
    if not is_homogeneous_ring(params):
        if mode != 0:
            raise ValidationError(f"mode must be 0 (the leading eigenvalue) on a chain other "
                                  f"than the homogeneous ring, got {mode!r}")
        a = engine.jacobian(params)
        values, right = jnp.linalg.eig(a)
        i = jnp.argmax(jnp.where(values.imag > 0, values.real, -jnp.inf))
        left_values, left = jnp.linalg.eig(a.T)
        j = jnp.argmin(jnp.abs(left_values - values[i].conj()))
        q, p = right[:, i], left[:, j]
        omega = values[i].imag
    else:
        if mode not in (0, n / 2):
            raise ValidationError(f"mode must be 0 or N/2 = {n / 2} (a real mode shape), "
                                  f"got {mode!r}")
        block = _fourier_blocks(params, engine)[mode]
        values, right = jnp.linalg.eig(block)
        i = jnp.argmax(values.imag)
        omega = values[i].imag
        left_values, left = jnp.linalg.eig(block.T)
        j = jnp.argmin(left_values.imag)
        shape = jnp.asarray(np.cos(np.pi * 2 * mode * np.arange(n) / n) / np.sqrt(n))
        q = jnp.kron(right[:, i], shape)
        p = jnp.kron(left[:, j], shape)
    q = q / jnp.linalg.norm(q)
    p = p / jnp.vdot(p, q).conj()
    return omega, q, p


def _leading_growth(v_d, args):
    params, engine = args
    return jnp.max(_steady_sliding_eigenvalues(with_parameter(params, "v_d", v_d),
                                               engine).real)


@checks_as_nan
@eqx.filter_jit
def _hopf_leading(params: ChainParams, engine, guess, rtol, atol):
    """The Hopf point of any chain: Newton's method (optimistix) on the leading
    growth rate, with shapes (1,) as `_hopf_modes` gives them per mode.

    Derivatives by the implicit function theorem on the Hopf condition
    g(v_d, p) = Re lambda(v_d, p) = 0 (optimistix's `ImplicitAdjoint`): dv_d,H =
    -(dg/dp dp) / (dg/dv_d), with the derivative of a simple eigenvalue from its
    left and right eigenvectors, d lambda = w^T dJ v / (w^T v) (the rows of V^-1
    are the left eigenvectors: JAX's derivative of `eigvals`; Magnus, Econometric
    Theory 1 (1985) 179). Nothing differentiates an eigenvector: the slope
    dg/dv_d, a derivative already, is held constant (`HopfPoint.slope`), since its
    own derivative would need them."""
    sol = optx.root_find(_leading_growth, optx.Newton(rtol=rtol, atol=atol), guess,
                         (params, engine), max_steps=100, throw=False)
    at = with_parameter(params, "v_d", sol.value)
    values = _steady_sliding_eigenvalues(at, engine)
    slope = jax.grad(_leading_growth)(*jax.lax.stop_gradient((sol.value, (params, engine))))
    fields = (sol.value, jnp.abs(values[0].imag), slope, values[0].real,
              sol.stats["num_steps"])
    return (*(jnp.atleast_1d(a) for a in fields), sol.result)


def _hopf_roots(params: ChainParams, engine, guess, rtol: float = 1e-12,
                atol: float = 1e-12):
    """(v_d, omega, slope, residual, steps, result) of the Hopf point of `engine`'s
    model (as `check_engine` gives it): per Fourier mode on the homogeneous ring
    (`_hopf_modes`), of the leading eigenvalue otherwise (`_hopf_leading`), each of
    shape (modes,) (result: () or (modes,), optimistix's RESULTS). Traceable."""
    guess = jnp.asarray(guess, dtype=float)
    if is_homogeneous_ring(params):
        return _hopf_modes(params, engine, guess, rtol, atol)
    return _hopf_leading(params, engine, guess, rtol, atol)


def hopf_point(params: ChainParams, guess: float = 1.0, *,
               engine: AbstractEngine = Smoothed(),
               rtol: float = 1e-12, atol: float = 1e-12, throw: bool = True) -> HopfPoint:
    """The Hopf boundary of steady sliding. On the homogeneous ring, mode by mode:
    the root in v_d of each Fourier mode's growth rate max Re(lambda)(v_d) = 0
    (`growth_rates`). On any other chain (mistuned, open, other loads): the root of
    the leading growth rate, max Re(lambda) over the eigenvalues of the Jacobian
    (`leading_growth_rate`). Both by optimistix's Newton method with the derivative
    from JAX (the Jacobian of eq. (5) by `jax.jacfwd`, its eigenvalues
    differentiated by JAX). For eq. (1) with uniform damping and load the closed
    form is `hopf_vd_analytic`; for any law with uniform damping and load the root
    is that of 2 xi + (P_n/P) mu'(v_d) = 0 for every mode.

    Differentiable (`jax.grad`, `jax.jvp`) in every other parameter of every chain
    (coupling, masses, damping, stiffnesses, loads, the friction law's parameters
    and tables) and in the engine's eps, by the implicit function theorem on the Hopf condition
    g(v_d, p) = Re lambda(v_d, p) = 0 (optimistix's `ImplicitAdjoint`): d v_d,H =
    -(dg/dp dp) / (dg/dv_d), with d lambda = w^T dJ v / (w^T v) from the left and
    right eigenvectors of the Jacobian (Govaerts, *Numerical Methods for
    Bifurcations of Dynamical Equilibria*, SIAM 2000, Ch. 4); no eigenvector is
    differentiated.

    **Arguments:**

    - `params`: the chain parameters (a `ChainParams`); `params.v_d` is ignored.
    - `guess`: starting belt speed of Newton's method, a finite number > 0 (a law
        with several Hopf points, such as a Stribeck curve, gives the one Newton's
        method reaches).
    - `engine`: the engine whose model's steady sliding is analysed
        (`AbstractEngine.jacobian` at steady sliding): `Smoothed()` (eps = 1e-3) by
        default, smoothed at its `Smoothed.eps`, traced: differentiable in it
        (implicitly, as in the other parameters), and a new value does not
        recompile. `Exact()` gives the limit eps -> 0 (the slip law's slope).
    - `rtol`, `atol`: Newton tolerances on v_d, finite numbers > 0.
    - `throw`: raise if Newton's method fails for a mode (the default), or give NaN
        as that mode's `v_d`, so that a failed solve never passes for a belt speed
        (as `throw` of `diffrax.diffeqsolve`); with `throw=False` it traces under
        `jax.jit` and `jax.jvp` (`hopf_vd`).

    **Returns:**

    A `HopfPoint`, fields of shape (n_osc,) on the homogeneous ring (one per Fourier
    mode), (1,) otherwise (the leading eigenvalue).

    **Raises:**

    `TypeError` if `params` is not a `ChainParams`, `engine` not an engine, or
    `guess`, `rtol` or `atol` not a real number;
    `ValidationError` naming `guess`, `rtol` or `atol` for a value that is not
    a finite number > 0; `RuntimeError` with `throw=True` if Newton's method fails for
    a mode or gives v_d <= 0 (try another `guess`).
    """
    check_params(params)
    for name, value, what in (("guess", guess, "belt speed"), ("rtol", rtol, "number"),
                              ("atol", atol, "number")):
        a = real_array(value, name)
        if a.ndim != 0 or not (np.isfinite(a) and a > 0):
            raise ValidationError(f"{name} must be a finite {what} > 0, got {a.tolist()!r}")
    engine = check_engine(engine)
    v, omega, slope, residual, steps, result = _hopf_roots(params, engine, guess, rtol, atol)
    found = (result == optx.RESULTS.successful) & (v > 0)
    if not throw:
        v = jnp.where(found, v, jnp.nan)
    elif not bool(jnp.all(found)):
        raise RuntimeError(f"Newton's method did not find the Hopf point from v_d = {guess}; "
                           "try another guess")
    return HopfPoint(v_d=v, omega=omega, slope=slope, residual=residual, newton_steps=steps)


def hopf_vd(params: ChainParams, guess: float = 1.0, *,
            engine: AbstractEngine = Smoothed()) -> Float[Array, ""]:
    """The Hopf belt speed of steady sliding (the largest over the Fourier modes of
    the homogeneous ring, that of the leading eigenvalue on any other chain):
    `hopf_point` with `throw=False`, reduced to one number. Traceable and
    differentiable in `params` and the eps of `engine` (as `hopf_point` takes it;
    `Smoothed()` by default) by implicit differentiation through optimistix's
    Newton method.

    **Returns:**

    A scalar; NaN (and a NaN derivative) where Newton's method failed for a mode
    or gave v_d <= 0.

    **Raises:**

    As `hopf_point` for a bad `guess` or `engine`.
    """
    return jnp.max(hopf_point(params, guess, engine=engine, throw=False).v_d)


def hopf_speed(params: ChainParams, engine: AbstractEngine = Smoothed()) -> float:
    """The Hopf belt speed of steady sliding as a number: the closed form of eq. (1)
    where it holds (`hopf_vd_analytic`: the exponential law with uniform damping,
    load and law, xi > 0, mu_st > mu_d; the limit eps -> 0, which differs from the
    smoothed one by `hopf_eps_correction`, 1e-1000 at eps = 1e-3), else Newton's
    method on the eigenvalues of the Jacobian of `engine`'s model (`hopf_vd`;
    `Smoothed()` by default); NaN where neither finds one."""
    try:
        return float(hopf_vd_analytic(params))
    except ValueError:
        return float(hopf_vd(params, engine=engine))
