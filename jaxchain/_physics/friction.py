"""Friction laws mu(v_rel) as objects (eq. (1) of the paper and others). The
friction force they give on a chain is in `forces`."""

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._errors import ValidationError


def as_parameter(value):
    """A parameter value as a float64 NumPy array (a leaf that `eqx.filter_jit`
    traces, so that a new value does not recompile), or the JAX array or tracer
    itself. Strings, booleans and None become object arrays, which `check_values`
    refuses with a `TypeError`."""
    if isinstance(value, jax.core.Tracer) or isinstance(value, jax.Array):
        return value
    try:
        kind = np.asarray(value).dtype.kind
    except ValueError:  # ragged nested lists
        kind = "O"
    if kind not in "iuf":
        return np.asarray(value, dtype=object)
    return np.asarray(value, dtype=np.float64)


def concrete(value) -> np.ndarray | None:
    """`value` as a NumPy array, or None when it is a tracer (checked later by
    whoever traces it)."""
    if isinstance(value, jax.core.Tracer):
        return None
    return np.asarray(value, dtype=float)


def check_values(owner: str, values: dict, rules: dict) -> None:
    """Validate concrete parameter values: each must be real, finite and satisfy
    its rule.

    **Arguments:**

    - `owner`: the class name used in messages, for example "Stribeck".
    - `values`: field name -> value.
    - `rules`: field name -> (predicate on a NumPy array, requirement as text).

    **Raises:**

    `TypeError` for a value that is not real numbers; `ValidationError` naming the
    field for a non-finite value or one that breaks its rule.
    """
    for name, value in values.items():
        if isinstance(value, np.ndarray) and value.dtype == object:
            raise TypeError(f"{owner}.{name} must be a real number (or an array of "
                            f"them), got {value.tolist()!r}")
        a = concrete(value)
        if a is None:
            continue
        shown = a.item() if a.ndim == 0 else a
        if not np.all(np.isfinite(a)):
            raise ValidationError(f"{owner}.{name} must be finite, got {shown!r}")
        ok, requirement = rules.get(name, (lambda a: True, ""))
        if not np.all(ok(a)):
            raise ValidationError(f"{owner}.{name} must be {requirement}, got {shown!r}")


def _positive(a):
    return a > 0


def _non_negative(a):
    return a >= 0


class AbstractFrictionLaw(eqx.Module):
    """A friction law: the friction coefficient mu as an even function of the
    relative velocity v_rel = x' - v_d, and its static value mu(0), which bounds the
    force in stick. The sign of the force (sign(v_rel), or its smoothing
    tanh(v_rel/eps)) is not part of the law.

    Every field is a scalar (the same law for every oscillator) or an array of
    shape (n_osc,) (one value per oscillator); `ChainParams` checks the shapes.
    Fields are float64 arrays, traced by `eqx.filter_jit`.
    """

    @abc.abstractmethod
    def __call__(self, v_rel: Float[ArrayLike, "*shape"]) -> Float[Array, "*shape"]:
        """mu(v_rel), broadcast against the law's fields; dimensionless."""

    def of_slip_speed(self, speed: Float[ArrayLike, "*shape"]) -> Float[Array, "*shape"]:
        """mu within a slip phase as a function of the slip speed u = s v_rel (s the
        phase's direction, u >= 0 during the phase): mu(|u|), moved off u = 0 by
        the smallest normal number, so that a phase that begins at v_rel = 0 (after
        a stick or a reversal) has the derivative mu'(0+) of its side there, where
        JAX's derivative of |.| is 0. Past u = 0 (a step that overshoots the end of
        the phase) it is the law mirrored, mu(|u|), which pulls the state back:
        an analytic continuation (exp(-u/v0) for eq. (1)) would push it on and
        make a phase that begins tangentially, at a breakaway from stick, chatter."""
        return self(speed + jnp.where(speed == 0, jnp.finfo(jnp.result_type(speed)).tiny, 0.0))

    @abc.abstractmethod
    def static(self) -> Float[Array, "*shape"]:
        """mu(0), the static friction coefficient: the bound |F| <= P_n mu(0) of the
        set-valued stick condition."""

    def check(self) -> None:
        """Validate the fields (called by each law's `__check_init__`)."""
        check_values(type(self).__name__,
                     {name: getattr(self, name) for name in self.parameter_names()},
                     self.rules())

    @classmethod
    def parameter_names(cls) -> tuple[str, ...]:
        """The names of the law's parameters (its fields), in order."""
        return tuple(f for f in cls.__dataclass_fields__)

    def scaled(self, velocity: float) -> "AbstractFrictionLaw":
        """The law with its velocities divided by `velocity` (a law in m/s made
        dimensionless by the velocity scale x_0 omega_n, `from_physical`): mu~(v~) =
        mu(v~ velocity).

        **Raises:** `ValidationError` for a law that does not say how (a user's law:
        give it dimensionless)."""
        raise ValidationError(f"{type(self).__name__} does not say how to rescale its "
                              "velocities: give it in dimensionless velocities")

    @classmethod
    def table_names(cls) -> tuple[str, ...]:
        """The parameters that hold a table (shape (m,), the same for every
        oscillator) rather than one value or one per oscillator; none but in
        `Tabulated`."""
        return ()

    @classmethod
    def ordered_pairs(cls) -> tuple[tuple[str, str], ...]:
        """(upper, lower) pairs of parameters that the law requires in order, upper
        >= lower: the static coefficient above the dynamic one (`mu_st` >= `mu_d`
        of eq. (1)); none unless a law says so. The identification keeps them in
        order by its parametrisation."""
        return ()

    @classmethod
    @abc.abstractmethod
    def rules(cls) -> dict:
        """field name -> (predicate, requirement text), for `check_values`."""


class ExponentialDecay(AbstractFrictionLaw):
    """The exponentially decaying law of eq. (1) of the paper, the default:

        mu(v_rel) = mu_d + (mu_st - mu_d) exp(-|v_rel| / v0).

    **Arguments:**

    - `mu_st`: static coefficient mu(0) (>= mu_d).
    - `mu_d`: dynamic coefficient, the limit for large |v_rel| (> 0).
    - `v0`: velocity scale of the decay (> 0).

    The defaults are eq. (7) of the paper (mu_d = 0.5, mu_st / mu_d = 2, v0 = 0.5).

    **Raises:**

    `ValidationError` naming the field for a non-finite value, mu_d <= 0, v0 <= 0 or
    mu_st < mu_d.
    """

    mu_st: ArrayLike = eqx.field(converter=as_parameter, default=1.0)
    mu_d: ArrayLike = eqx.field(converter=as_parameter, default=0.5)
    v0: ArrayLike = eqx.field(converter=as_parameter, default=0.5)

    def __check_init__(self):
        self.check()
        mu_st, mu_d = concrete(self.mu_st), concrete(self.mu_d)
        if mu_st is not None and mu_d is not None and not np.all(mu_st >= mu_d):
            raise ValidationError(f"ExponentialDecay.mu_st must be >= mu_d = {mu_d.tolist()!r}, "
                                  f"got {mu_st.tolist()!r}")

    @classmethod
    def rules(cls):
        return {"mu_d": (_positive, "> 0"), "v0": (_positive, "> 0")}

    @classmethod
    def ordered_pairs(cls):
        return (("mu_st", "mu_d"),)

    def __call__(self, v_rel):
        return self.mu_d + (self.mu_st - self.mu_d) * jnp.exp(-jnp.abs(v_rel) / self.v0)

    def scaled(self, velocity):
        return eqx.tree_at(lambda f: f.v0, self, self.v0 / velocity)

    def static(self):
        return jnp.asarray(self.mu_st)


class Stribeck(AbstractFrictionLaw):
    """A Stribeck curve with a viscous term (for example Berger (2002), Appl. Mech.
    Rev. 55, 535-577):

        mu(v_rel) = mu_c + (mu_s - mu_c) exp(-(|v_rel| / v_s)^delta) + viscous |v_rel|.

    **Arguments:**

    - `mu_s`: static coefficient mu(0) (>= mu_c).
    - `mu_c`: Coulomb (kinetic) level (> 0).
    - `v_s`: Stribeck velocity (> 0).
    - `delta`: shape exponent (> 0; 1 is exponential, 2 Gaussian).
    - `viscous`: viscous coefficient (>= 0).

    **Raises:**

    `ValidationError` naming the field for a non-finite value, mu_c <= 0, v_s <= 0,
    delta <= 0, viscous < 0 or mu_s < mu_c.
    """

    mu_s: ArrayLike = eqx.field(converter=as_parameter, default=1.0)
    mu_c: ArrayLike = eqx.field(converter=as_parameter, default=0.5)
    v_s: ArrayLike = eqx.field(converter=as_parameter, default=0.5)
    delta: ArrayLike = eqx.field(converter=as_parameter, default=2.0)
    viscous: ArrayLike = eqx.field(converter=as_parameter, default=0.0)

    def __check_init__(self):
        self.check()
        mu_s, mu_c = concrete(self.mu_s), concrete(self.mu_c)
        if mu_s is not None and mu_c is not None and not np.all(mu_s >= mu_c):
            raise ValidationError(f"Stribeck.mu_s must be >= mu_c = {mu_c.tolist()!r}, "
                                  f"got {mu_s.tolist()!r}")

    @classmethod
    def rules(cls):
        return {"mu_c": (_positive, "> 0"), "v_s": (_positive, "> 0"),
                "delta": (_positive, "> 0"), "viscous": (_non_negative, ">= 0")}

    @classmethod
    def ordered_pairs(cls):
        return (("mu_s", "mu_c"),)

    def __call__(self, v_rel):
        r = jnp.abs(v_rel) / self.v_s
        # (r^delta) has an infinite derivative at r = 0 for delta < 1: evaluate the
        # power away from 0 only, so that JAX's derivatives stay finite there.
        safe = jnp.where(r > 0, r, 1.0)
        decay = jnp.where(r > 0, jnp.exp(-safe**self.delta), 1.0)
        return self.mu_c + (self.mu_s - self.mu_c) * decay + self.viscous * jnp.abs(v_rel)

    def scaled(self, velocity):
        return eqx.tree_at(lambda f: (f.v_s, f.viscous), self,
                           (self.v_s / velocity, self.viscous * velocity))

    def static(self):
        return jnp.asarray(self.mu_s)


class Polynomial(AbstractFrictionLaw):
    """A cubic law in |v_rel|, common in brake-squeal models (for example Hoffmann
    et al. (2002), Mech. Syst. Signal Process. 16, 613-627):

        mu(v_rel) = c0 + c1 |v_rel| + c2 v_rel^2 + c3 |v_rel|^3.

    **Arguments:**

    - `c0`: static coefficient mu(0) (> 0).
    - `c1`, `c2`: linear and quadratic coefficients (any sign; c1 < 0 gives the
        falling characteristic that destabilises steady sliding).
    - `c3`: cubic coefficient (>= 0, so that mu does not fall without bound).

    The defaults (1, -0.5, 0, 0.1) fall from 1 to a minimum of 0.53 at |v_rel| = 1.29.

    **Raises:**

    `ValidationError` naming the field for a non-finite value, c0 <= 0, c3 < 0, or
    coefficients for which mu(v_rel) <= 0 at some |v_rel| <= 100.
    """

    c0: ArrayLike = eqx.field(converter=as_parameter, default=1.0)
    c1: ArrayLike = eqx.field(converter=as_parameter, default=-0.5)
    c2: ArrayLike = eqx.field(converter=as_parameter, default=0.0)
    c3: ArrayLike = eqx.field(converter=as_parameter, default=0.1)

    def __check_init__(self):
        self.check()
        c = [concrete(getattr(self, name)) for name in ("c0", "c1", "c2", "c3")]
        if all(a is not None for a in c):
            s = np.linspace(0.0, 100.0, 100001)[:, None]
            mu = c[0] + c[1] * s + c[2] * s**2 + c[3] * s**3
            if not np.all(mu > 0):
                raise ValidationError("Polynomial coefficients must keep mu(v_rel) > 0 for "
                                      f"|v_rel| <= 100, got c0..c3 = {[a.tolist() for a in c]!r}")

    @classmethod
    def rules(cls):
        return {"c0": (_positive, "> 0"), "c3": (_non_negative, ">= 0")}

    def __call__(self, v_rel):
        s = jnp.abs(v_rel)
        return self.c0 + s * (self.c1 + s * (self.c2 + s * self.c3))

    def scaled(self, velocity):
        return eqx.tree_at(lambda f: (f.c1, f.c2, f.c3), self,
                           (self.c1 * velocity, self.c2 * velocity**2, self.c3 * velocity**3))

    def static(self):
        return jnp.asarray(self.c0)


class Coulomb(AbstractFrictionLaw):
    """Constant friction, mu(v_rel) = mu (>= 0): Coulomb's law. Steady sliding is then
    stable for any xi > 0 (no falling characteristic). mu = 0 switches friction
    off (the linear chain, against which a forced chain's friction damping is
    measured).

    **Raises:**

    `ValidationError` for a non-finite or negative mu.
    """

    mu: ArrayLike = eqx.field(converter=as_parameter, default=0.5)

    def __check_init__(self):
        self.check()

    @classmethod
    def rules(cls):
        return {"mu": (_non_negative, ">= 0")}

    def __call__(self, v_rel):
        return self.mu + 0.0 * jnp.abs(v_rel)

    def scaled(self, velocity):
        return self

    def static(self):
        return jnp.asarray(self.mu)


def _table_speeds(value) -> tuple:
    """The speeds of a table as a tuple of floats (a static, hashable field)."""
    try:
        return tuple(float(v) for v in np.asarray(value, dtype=float).reshape(-1))
    except (TypeError, ValueError):
        raise ValidationError(f"Tabulated.v must be real numbers, got {value!r}") from None


class Tabulated(AbstractFrictionLaw):
    """A friction law from measured samples: mu at relative speeds v_1 < v_2 < ...
    (v >= 0; mu(-v) = mu(v)), interpolated by a monotone piecewise cubic Hermite
    interpolant (PCHIP, Fritsch & Carlson (1980), SIAM J. Numer. Anal. 17, 238-246,
    by `interpax.interp1d(method="monotonic")`): continuously differentiable,
    monotone between monotone samples, with no overshoot beyond the samples.

    Beyond the table mu is held at its end values: mu(|v|) = mu_1 for |v| < v_1 and
    mu_last for |v| > v_last. The static coefficient (the stick bound) is
    mu(0) = mu_1 (the first sample, at v_1 = 0 when the table starts there).

    **Arguments:**

    - `v`: the speeds, shape (m,), m >= 2, strictly increasing, >= 0, in the units of
        the chain's velocities (dimensionless, eq. (4); see `from_physical` for m/s).
        Static: a new table of speeds compiles anew.
    - `mu`: the friction coefficients, shape (m,), > 0 (traced: differentiable, for
        identification).

    **Raises:**

    `ValidationError` naming the field for fewer than 2 samples, speeds that are not
    sorted or negative, a NaN, or a coefficient <= 0 or of another length.
    """

    v: tuple = eqx.field(static=True, converter=_table_speeds)
    mu: ArrayLike = eqx.field(converter=as_parameter)

    def __check_init__(self):
        speeds = np.asarray(self.v, dtype=float)
        if speeds.size < 2:
            raise ValidationError(f"Tabulated.v needs at least 2 samples, got {speeds.size}")
        if not np.all(np.isfinite(speeds)):
            raise ValidationError("Tabulated.v must be finite, got a NaN or an infinity")
        if speeds[0] < 0:
            raise ValidationError(f"Tabulated.v must be >= 0 (mu is even in v), got "
                                  f"{speeds[0]!r}")
        if not np.all(np.diff(speeds) > 0):
            i = int(np.flatnonzero(np.diff(speeds) <= 0)[0])
            raise ValidationError(f"Tabulated.v must be strictly increasing, got "
                                  f"{speeds[i]!r} then {speeds[i + 1]!r}")
        if np.shape(self.mu) != speeds.shape:
            raise ValidationError(f"Tabulated.mu must have the shape of v, {speeds.shape}, "
                                  f"got {np.shape(self.mu)}")
        self.check()

    @classmethod
    def rules(cls):
        return {"mu": (_positive, "> 0")}

    @classmethod
    def parameter_names(cls) -> tuple[str, ...]:
        return ("mu",)

    @classmethod
    def table_names(cls) -> tuple[str, ...]:
        return ("mu",)

    @classmethod
    def from_csv(cls, path) -> "Tabulated":
        """A table read from a CSV file with a header naming the columns `v` and
        `mu` (other columns are ignored).

        **Raises:** `ValidationError` naming the file for a file that cannot be read,
        a missing column, or a value that is not a number (or the table's errors)."""
        import csv

        try:
            with open(path, newline="") as f:
                rows = list(csv.DictReader(f))
        except OSError as err:
            raise ValidationError(f"{path}: cannot read it ({err.strerror})") from None
        if not rows or not {"v", "mu"} <= set(rows[0]):
            raise ValidationError(f"{path}: needs a header with the columns v and mu")
        try:
            v = [float(r["v"]) for r in rows]
            mu = [float(r["mu"]) for r in rows]
        except (TypeError, ValueError):
            raise ValidationError(f"{path}: a value in column v or mu is not a number") \
                from None
        try:
            return cls(v=v, mu=mu)
        except ValidationError as err:
            raise ValidationError(f"{path}: {err}") from None

    def __call__(self, v_rel):
        import interpax

        speeds = jnp.asarray(self.v)
        s = jnp.clip(jnp.abs(jnp.asarray(v_rel)), speeds[0], speeds[-1])
        flat = jnp.reshape(s, (-1,))
        values = jnp.asarray(self.mu)
        with jax.numpy_rank_promotion("allow"):  # interpax broadcasts inside
            # the PCHIP slopes at the samples, then the cubic Hermite evaluation with
            # them: the same interpolant as method="monotonic", at a fifth of its cost
            slopes = interpax.approx_df(speeds, values, method="monotonic")
            mu = interpax.interp1d(flat, speeds, values, method="cubic", fx=slopes,
                                   extrap=True, even_spacing=self._evenly_spaced())
        return jnp.reshape(mu, jnp.shape(s))

    def scaled(self, velocity):
        return Tabulated(v=np.asarray(self.v) / velocity, mu=self.mu)

    def _evenly_spaced(self) -> bool:
        """Whether the speeds are evenly spaced (to 1e-12 of their step): interpax
        then finds a speed's interval by division instead of a search."""
        steps = np.diff(np.asarray(self.v))
        return bool(np.all(np.abs(steps - steps[0]) <= 1e-12 * steps[0]))

    def static(self):
        return jnp.asarray(self.mu)[0]


#: The friction laws by the names the command line takes (`--friction NAME:...`).
FRICTION_LAWS = {"exponential": ExponentialDecay, "stribeck": Stribeck,
                 "polynomial": Polynomial, "coulomb": Coulomb, "table": Tabulated}
