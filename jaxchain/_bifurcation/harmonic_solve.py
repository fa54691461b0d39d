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
N (2H + 1) + 1."""

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
