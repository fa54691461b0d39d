"""The linear solve of harmonic balance's Newton steps, exploiting the structure of
its Jacobian: the friction force of oscillator n depends on that oscillator's
velocity only, so the friction term couples the harmonics of one oscillator and no
two oscillators; the coupling springs eta_c couple oscillators harmonic by
harmonic. With the unknowns ordered (harmonic, oscillator), the Jacobian is a
block-diagonal matrix over the oscillators (blocks of size 2H + 1: the oscillator's
own stiffness, damping, inertia and friction) plus the coupling and the period's
column. GMRES (lineax) solves it, preconditioned by the inverse of the block
diagonal (block Jacobi; Saad, *Iterative Methods for Sparse Linear Systems*, 2nd
ed. (2003), Sect. 10.2): on a weakly coupled chain it converges in a few
iterations, at the cost of N factorizations of size 2H + 2 instead of one of size
N (2H + 1) + 1. On a ring or a line, block elimination over the oscillators solves
it directly (`ring_factors`, `CyclicBlockLU`)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import lineax as lx
import numpy as np


class BlockJacobiGMRES(lx.AbstractLinearSolver):
    """GMRES preconditioned by the oscillator blocks of a harmonic-balance Jacobian
    (this module's docstring), for unknowns laid out as `HarmonicBalance`'s: the
    coefficients (2H + 1, n_osc) flattened row by row, then the period; the last
    equation (the phase condition or the period's) joins the block of
    `phase_oscillator`, which carries the period's column.

    The blocks are read from the operator itself, by 2H + 2 products with probe
    vectors (each probe sets one harmonic of every oscillator at once, and one the
    period): the coupling adds to a block's diagonal only (it is diagonal in the
    harmonics), which the preconditioner then holds approximately; GMRES corrects
    for what the blocks leave out.

    **Arguments:**

    - `harmonics`: H; `n_osc`: the chain's oscillators; `phase_oscillator`: the
        oscillator of the phase condition.
    - `rtol`, `atol`: GMRES's tolerances on the residual (lineax, max norm).
    - `restart`, `max_steps`: GMRES's restart length and iteration budget.
    """

    harmonics: int = eqx.field(static=True)
    n_osc: int = eqx.field(static=True)
    phase_oscillator: int = eqx.field(static=True)
    rtol: float = eqx.field(static=True, default=1e-12)
    atol: float = eqx.field(static=True, default=1e-12)
    restart: int = eqx.field(static=True, default=40)
    max_steps: int = eqx.field(static=True, default=400)

    def _gmres(self) -> lx.GMRES:
        return lx.GMRES(rtol=self.rtol, atol=self.atol, restart=self.restart,
                        max_steps=self.max_steps)

    def init(self, operator, options):
        return operator, self._preconditioner(operator)

    def _preconditioner(self, operator) -> lx.FunctionLinearOperator:
        m, n, p = 2 * self.harmonics + 1, self.n_osc, self.phase_oscillator
        size = m * n + 1
        probes = np.zeros((m + 1, size))
        for j in range(m):
            probes[j, j * n:(j + 1) * n] = 1.0
        probes[m, -1] = 1.0
        columns = jax.vmap(operator.mv)(jnp.asarray(probes))  # (m + 1, size)
        last_row = operator.transpose().mv(jnp.zeros(size).at[-1].set(1.0))
        # block n: rows i*n + n, columns j (harmonic j of every oscillator)
        blocks = jnp.transpose(jnp.reshape(columns[:m, :m * n], (m, m, n)), (2, 1, 0))
        period_column = jnp.reshape(columns[m, :m * n], (m, n)).T  # (n, m)
        closing_row = jnp.reshape(last_row[:m * n], (m, n)).T  # (n, m)
        is_p = (jnp.arange(n) == p)[:, None]
        augmented = jnp.concatenate([
            jnp.concatenate([blocks, jnp.where(is_p, period_column, 0.0)[:, :, None]], axis=2),
            jnp.concatenate([jnp.where(is_p, closing_row, 0.0),
                             jnp.where(is_p[:, 0], last_row[-1], 1.0)[:, None]],
                            axis=1)[:, None, :]], axis=1)  # (n, m + 1, m + 1)
        lu = jax.vmap(jsl.lu_factor)(augmented)

        def apply(z):
            zc = jnp.reshape(z[:-1], (m, n)).T  # (n, m)
            rhs = jnp.concatenate([zc, jnp.where(is_p[:, 0], z[-1], 0.0)[:, None]], axis=1)
            y = jax.vmap(jsl.lu_solve)(lu, rhs)  # (n, m + 1)
            return jnp.concatenate([jnp.ravel(y[:, :m].T), y[p, m:]])

        return lx.FunctionLinearOperator(apply, operator.in_structure())

    def compute(self, state, vector, options):
        operator, preconditioner = state
        gmres = self._gmres()
        return gmres.compute(gmres.init(operator, {}), vector,
                             {"preconditioner": preconditioner})

    def transpose(self, state, options):
        operator, preconditioner = state
        return (operator.transpose(), preconditioner.transpose()), options

    def conj(self, state, options):
        operator, preconditioner = state
        return (lx.conj(operator), lx.conj(preconditioner)), options

    def assume_full_rank(self):
        return True


class CyclicBlockLU(lx.AbstractLinearSolver):
    """Direct solve of a harmonic-balance Jacobian on a ring or a line of
    oscillators (`ring_factors`), for a matrix operator laid out as
    `HarmonicBalance`'s unknowns: the coefficients (2H + 1, n_osc) flattened row by
    row, then `border` trailing unknowns (the period; a continued parameter's in a
    bordered continuation system) with as many trailing equations. The matrix is
    read from the operator (`as_matrix`); `couples_as_ring` tells whether a chain's
    Jacobians have the structure assumed.

    **Arguments:** `harmonics`: H; `n_osc`: the oscillators (>= 2); `border`: the
    trailing unknowns (>= 1).
    """

    harmonics: int = eqx.field(static=True)
    n_osc: int = eqx.field(static=True)
    border: int = eqx.field(static=True, default=1)

    def init(self, operator, options):
        matrix = operator.as_matrix()
        m, n, size = 2 * self.harmonics + 1, self.n_osc, (2 * self.harmonics + 1) * self.n_osc
        blocks = jnp.reshape(matrix[:size, :size], (m, n, m, n))
        own = jnp.transpose(jnp.diagonal(blocks, axis1=1, axis2=3), (2, 0, 1))
        # advanced indices apart put their axis first: (K, m, m)
        return ring_factors(own, lambda i, j: blocks[:, i, :, j],
                            matrix[:size, size:], matrix[size:, :size],
                            matrix[size:, size:]), operator

    def compute(self, state, vector, options):
        factors, _ = state
        return ring_solve(factors, vector), lx.RESULTS.successful, {}

    def transpose(self, state, options):
        _, operator = state
        return self.init(operator.transpose(), options), options

    def conj(self, state, options):
        _, operator = state
        return self.init(lx.conj(operator), options), options

    def assume_full_rank(self):
        return True


def ring_factors(own, coupling, columns, rows, corner):
    """The factors of a harmonic-balance Jacobian on a ring or a line of oscillators
    with a border, by block elimination over the oscillators: block LU of the
    block tridiagonal part over oscillators 0..n - 2 (the Thomas algorithm; Golub
    and Van Loan, *Matrix Computations*, 4th ed. (2013), Sect. 4.5.1), the last
    oscillator and the border eliminated by their Schur complement (a ring's
    closing links join them). It costs about 5 n (2H + 1)^3 operations where LU
    of the whole matrix costs (n (2H + 1))^3 / 3.

    **Arguments** (m = 2H + 1 coefficients per oscillator, n oscillators, k border
    unknowns; the coefficients ordered (harmonic, oscillator) as
    `HarmonicBalance`'s unknowns):

    - `own`: the oscillators' diagonal blocks, shape (n, m, m);
    - `coupling(i, j)`: the blocks of oscillators i and j, i != j, for index arrays
        of one length K, shape (K, m, m); oscillators 0..n - 2 must couple only to
        their neighbours (`couples_as_ring`);
    - `columns`, `rows`: the border's columns (n m, k) and rows (k, n m);
    - `corner`: the border's own block (k, k).

    Returns the factors that `ring_solve` takes."""
    n, m = own.shape[0], own.shape[1]
    k = corner.shape[0]
    q = n - 1
    idx = np.arange(q)
    columns = jnp.transpose(jnp.reshape(columns, (m, n, k)), (1, 0, 2))  # (n, m, k)
    rows = jnp.transpose(jnp.reshape(rows, (k, m, n)), (0, 2, 1))  # (k, n, m)
    # U_i = A[i, i + 1], i < q - 1; L_i = A[i, i - 1], i >= 1 (none for two oscillators)
    upper = coupling(idx[:-1], idx[1:]) if q > 1 else jnp.zeros((0, m, m), own.dtype)
    lower = coupling(idx[1:], idx[:-1]) if q > 1 else jnp.zeros((0, m, m), own.dtype)
    last = np.full(q, q)
    border_columns = jnp.concatenate([coupling(idx, last), columns[:q]], axis=2)
    border_rows = jnp.concatenate([jnp.transpose(coupling(last, idx), (1, 0, 2)),
                                   rows[:, :q]], axis=0)  # (m + k, q, m)
    corner = jnp.concatenate([jnp.concatenate([own[q], columns[q]], axis=1),
                              jnp.concatenate([rows[:, q], corner], axis=1)])

    def pivot(previous, x):  # G_i = D_i - L_i W_i, W_i = G_{i-1}^-1 U_{i-1}
        d, l_i, u_previous = x
        w = jsl.lu_solve(previous, u_previous)
        g = jsl.lu_factor(d - l_i @ w)
        return g, (g, w)

    first = jsl.lu_factor(own[0])
    _, ((lu, piv), ws) = jax.lax.scan(pivot, first, (own[1:q], lower, upper))
    tridiagonal = ((jnp.concatenate([first[0][None], lu]),
                    jnp.concatenate([first[1][None], piv])), ws, lower)
    z = _tridiagonal_solve(tridiagonal, border_columns)  # (q, m, m + k)
    schur = jsl.lu_factor(corner - jnp.einsum("bqm,qmc->bc", border_rows, z))
    return tridiagonal, z, border_rows, schur


def _tridiagonal_solve(tridiagonal, r):
    """Forward elimination and back substitution of the block tridiagonal part, for
    the right-hand sides r, shape (q, m, K)."""
    (lu, piv), ws, lower = tridiagonal

    def forward(previous, x):
        lu_i, piv_i, l_i, r_i = x
        z_i = jsl.lu_solve((lu_i, piv_i), r_i - l_i @ previous)
        return z_i, z_i

    z0 = jsl.lu_solve((lu[0], piv[0]), r[0])
    _, zs = jax.lax.scan(forward, z0, (lu[1:], piv[1:], lower, r[1:]))

    def backward(following, x):
        z_i, w_next = x
        x_i = z_i - w_next @ following
        return x_i, x_i

    zs = jnp.concatenate([z0[None], zs])
    _, xs = jax.lax.scan(backward, zs[-1], (zs[:-1], ws), reverse=True)
    return jnp.concatenate([xs, zs[-1:]])


def ring_solve(factors, vector):
    """The solution of the system `ring_factors` factored, for the right-hand side
    `vector` laid out as its unknowns, shape (n m + k,)."""
    tridiagonal, z, border_rows, schur = factors
    q, m = z.shape[0], z.shape[1]
    n, size = q + 1, (q + 1) * m
    r = jnp.reshape(vector[:size], (m, n)).T  # (n, m)
    y = _tridiagonal_solve(tridiagonal, r[:q, :, None])[..., 0]  # (q, m)
    s = jsl.lu_solve(schur, jnp.concatenate([r[q], vector[size:]])
                     - jnp.einsum("bqm,qm->b", border_rows, y))
    x = jnp.concatenate([y - jnp.einsum("qmb,b->qm", z, s), s[None, :m]])  # (n, m)
    return jnp.concatenate([jnp.ravel(x.T), s[m:]])


def couples_as_ring(params) -> bool:
    """Whether `ring_factors` solves `params`' harmonic-balance Jacobians: eq.
    (5) couples oscillators by its graph's links only, and none joins two of the
    oscillators 0..n_osc - 2 that are not neighbours (a line, or a ring: its
    closing link touches the last oscillator)."""
    last = params.n_osc - 1
    return params.n_osc >= 2 and all(abs(left - right) == 1 for left, right in params.graph.links
                                     if left < last and right < last)
