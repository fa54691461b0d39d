"""Physical parameters of the chain (eqs. (4)-(7) of the paper, generalised to any
chain: per-oscillator values, open ends and any friction law)."""

import dataclasses
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike

from .chain import Graph, as_graph
from .forcing import Forcing
from .mistuning import Mistuning
from .scales import Scales
from .friction import AbstractFrictionLaw, ExponentialDecay, as_parameter, check_values
from .._checks import check_count
from .._errors import ValidationError
from .._setup import check_float64

#: The fields that hold one value per chain (never per oscillator).
CHAIN_SCALARS = ("v_d",)
#: The fields that may hold one value per oscillator, shape (n_osc,).
PER_OSCILLATOR = ("xi", "stiffness", "load", "mass")


def _optional_parameter(value):
    """None as it is (a field that is not given), else `as_parameter`."""
    return None if value is None else as_parameter(value)


#: Marks a shorthand argument of `ChainParams` that was not given.
_ABSENT = object()

#: Where eps went: the error for eps given to the chain, as before.
EPS_MOVED = ("ChainParams.eps: eps is a setting of the smoothed engine, not of the chain: "
             "give engine=jaxchain.Smoothed(eps=...) (--eps on the command line)")


class ChainParams(eqx.Module):
    """Dimensionless parameters of a chain of friction-excited oscillators, eq. (5)
    of the paper *Multiple spatially localized dynamical states in friction-excited
    oscillator chains*, generalised:

        x_n'' = -2 xi_n x_n' - k_n x_n - (coupling)_n + (P_n/P) F(x_n' - v_d),

    with the coupling of `coupling_force` (eta_c (2 x_n - x_{n+1} - x_{n-1}) on the
    paper's ring) and F the friction law's force. The chain holds physics only: how
    sign(v_rel) is treated is the engine's (`Smoothed(eps=...)` smooths it as
    tanh(v_rel/eps), `Exact` switches between stick and slip).

    All quantities are dimensionless as in eqs. (4)-(6): displacements in units of
    x_0 = P/k, velocities in units of x_0*omega_n, time in units of 1/omega_n.

    **Arguments:**

    - `n_osc`: number of oscillators N (static, >= 1).
    - `xi`: damping ratio (>= 0), shape () or (n_osc,).
    - `eta_c`: coupling stiffness k_c/k (>= 0), shape () or (n_links,), one value
        per link of the graph, in its order (n_links = N on the ring, N - 1 on a
        free line, N + 1 on a fixed one, see `BOUNDARIES` and `Graph`).
    - `v_d`: belt speed (> 0, or >= 0 with a `forcing`; a belt moving the other
        way is the mirror image x -> -x), shape ().
    - `stiffness`: ground stiffness k_n/k = 1 + delta_n (> 0), shape () or (n_osc,).
    - `load`: normal load P_n/P, which scales oscillator n's friction force (> 0),
        shape () or (n_osc,).
    - `mass`: mass m_n/m (> 0), shape () or (n_osc,), or None for unit masses (the
        paper's chain; the time stays scaled by the reference oscillator's
        1/omega_n, so that m_n x_n'' = ... in eq. (5)).
    - `friction`: the friction law (an `AbstractFrictionLaw`), whose fields are
        each of shape () or (n_osc,); eq. (1), `ExponentialDecay()`, by default.
    - `boundary`: shorthand for `graph=Graph.line(n_osc, boundary)`: "ring" (eq. (5),
        the default), "free" or "fixed".
    - `graph`: the coupling `Graph` (static): a line, a 2-D lattice
        (`Graph.lattice`) or any links; n_osc is then the graph's (give either
        `graph` or `boundary`).
    - `scales`: the `Scales` of a chain made from SI units by `from_physical`
        (recorded in results; `to_physical` converts back), or None (static).
    - `mistuning`: the `Mistuning` record that drew `stiffness` (see `mistune`),
        or None (static).
    - `forcing`: a harmonic force on the oscillators (`Forcing`), or None (the
        paper's autonomous chain). With a forcing, v_d may be 0: a friction damper
        whose contact does not move.
    - `mu_st`, `mu_d`, `v0`: shorthand for `friction=ExponentialDecay(mu_st, mu_d,
        v0)`, eq. (1) (not stored; read them as `params.friction.mu_st`).

    The defaults are eq. (7) of the paper (xi = 0.05, mu_d = 0.5, mu_st/mu_d = 2,
    v0 = 0.5) with eta_c = 0.01, N = 20 and v_d = 1.5, the scene of Fig. 4, on the
    homogeneous ring.

    Array fields are stored as float64 arrays (JAX arrays or tracers are kept as
    they are, for example under `jax.vmap`), so that `eqx.filter_jit` traces them: a
    new value of v_d or xi does not recompile. Only concrete values are
    validated. Change a field with `with_parameter`, which validates. A batch of
    chains (lanes) is never made by giving a field a longer axis: see `lane_params`
    and `stack_chains`.

    **Raises:**

    `ValidationError` naming the field for eps (the smoothed engine's now), a
    non-finite value, n_osc < 1, xi < 0,
    eta_c < 0, v_d <= 0 (v_d < 0 with a forcing), stiffness <= 0, load <= 0,
    mass <= 0, a field of
    the wrong shape, an unknown boundary, both `graph` and `boundary`, a graph of
    another n_osc, a friction law that is not an
    `AbstractFrictionLaw`, both `friction` and `mu_st`/`mu_d`/`v0`, or a
    `stiffness` that its `mistuning` record does not give. The friction law
    validates its own parameters.
    `RuntimeError` when float64 is off in JAX (call `jaxchain.configure()` first).
    """

    n_osc: int = eqx.field(static=True)
    xi: ArrayLike = eqx.field(converter=as_parameter)
    eta_c: ArrayLike = eqx.field(converter=as_parameter)
    v_d: ArrayLike = eqx.field(converter=as_parameter)
    stiffness: ArrayLike = eqx.field(converter=as_parameter)
    load: ArrayLike = eqx.field(converter=as_parameter)
    mass: ArrayLike | None = eqx.field(converter=_optional_parameter)
    friction: AbstractFrictionLaw
    forcing: Forcing | None
    graph: Graph = eqx.field(static=True)
    mistuning: Mistuning | None = eqx.field(static=True)
    scales: Scales | None = eqx.field(static=True)

    def __init__(self, n_osc: int = _ABSENT, xi=0.05, eta_c=0.01, v_d=1.5,
                 stiffness=1.0, load=1.0, friction: AbstractFrictionLaw | None = None,
                 boundary: str = _ABSENT, mistuning: Mistuning | None = None, *,
                 mass=None, graph: Graph | None = None, scales: Scales | None = None,
                 forcing: Forcing | None = None, mu_st=_ABSENT, mu_d=_ABSENT, v0=_ABSENT,
                 eps=_ABSENT):
        check_float64()  # before the converters make arrays of the wrong precision
        if eps is not _ABSENT:
            raise ValidationError(EPS_MOVED)
        shorthand = {k: v for k, v in (("mu_st", mu_st), ("mu_d", mu_d), ("v0", v0))
                     if v is not _ABSENT}
        if friction is None:
            friction = ExponentialDecay(**shorthand)
        elif shorthand:
            raise ValidationError(f"ChainParams takes either friction or {', '.join(shorthand)} "
                                  "(the shorthand of ExponentialDecay), not both")
        if graph is not None and boundary is not _ABSENT:
            raise ValidationError("ChainParams takes either graph or boundary, not both")
        if graph is not None and not isinstance(graph, Graph):
            raise ValidationError(f"ChainParams.graph must be a jaxchain.Graph, got "
                                  f"{type(graph).__name__}")
        if n_osc is _ABSENT:
            n_osc = 20 if graph is None else graph.n_osc
        if graph is None:
            check_count("ChainParams.n_osc", n_osc)
            try:
                graph = as_graph("ring" if boundary is _ABSENT else boundary, n_osc)
            except ValidationError as err:
                raise ValidationError(f"ChainParams.{err}") from None
        elif graph.n_osc != n_osc:
            raise ValidationError(f"ChainParams.n_osc is {n_osc!r} but its graph has "
                                  f"{graph.n_osc} oscillators")
        self.n_osc = n_osc
        self.xi = xi
        self.eta_c = eta_c
        self.v_d = v_d
        self.stiffness = stiffness
        self.load = load
        self.mass = mass
        self.friction = friction
        self.forcing = forcing
        self.graph = graph
        self.mistuning = mistuning
        self.scales = scales

    @property
    def boundary(self) -> str:
        """The boundary of a line ("ring", "free", "fixed"), else the graph's kind
        ("lattice", "links")."""
        return self.graph.kind

    def __check_init__(self):
        if not isinstance(self.friction, AbstractFrictionLaw):
            raise ValidationError(f"ChainParams.friction must be a friction law (jaxchain."
                                  f"ExponentialDecay, Stribeck, Polynomial, Coulomb or another "
                                  f"AbstractFrictionLaw), got {type(self.friction).__name__}")
        if self.forcing is not None and not isinstance(self.forcing, Forcing):
            raise ValidationError(f"ChainParams.forcing must be a jaxchain.Forcing or None, "
                                  f"got {type(self.forcing).__name__}")
        if self.mistuning is not None and not isinstance(self.mistuning, Mistuning):
            raise ValidationError(f"ChainParams.mistuning must be a jaxchain.Mistuning or None, "
                                  f"got {type(self.mistuning).__name__}")
        positive = (lambda a: a > 0, "> 0")
        non_negative = (lambda a: a >= 0, ">= 0")
        names = ("xi", "eta_c", "v_d", "stiffness", "load", "mass")
        check_values("ChainParams", {name: getattr(self, name) for name in names
                                     if getattr(self, name) is not None},
                     {"xi": non_negative, "eta_c": non_negative,
                      "v_d": positive if self.forcing is None else non_negative,
                      "stiffness": positive, "load": positive,
                      "mass": positive})
        self._check_shapes()
        if self.mistuning is not None and not isinstance(self.stiffness, jax.core.Tracer):
            given = np.asarray(self.stiffness, dtype=float)
            if not np.array_equal(np.broadcast_to(given, (self.n_osc,)),
                                  self.mistuning.stiffness(self.n_osc)):
                raise ValidationError("ChainParams.stiffness is not the one its mistuning "
                                      f"record {self.mistuning} draws; set mistuning=None "
                                      "to give your own")

    def _check_shapes(self):
        n, links = self.n_osc, self.graph.n_links
        expected = {name: ((), (n,)) for name in PER_OSCILLATOR}
        expected |= {name: ((),) for name in CHAIN_SCALARS} | {"eta_c": ((), (links,))}
        for name, shapes in expected.items():
            if getattr(self, name) is None:
                continue
            shape = np.shape(getattr(self, name))
            if shape not in shapes:
                raise ValidationError(_shape_message(f"ChainParams.{name}", shape, shapes))
        for name in ("amplitude", "phase") if self.forcing is not None else ():
            shape = np.shape(getattr(self.forcing, name))
            if shape not in ((), (n,)):
                raise ValidationError(_shape_message(f"Forcing.{name}", shape, ((), (n,))))
        for name in self.friction.parameter_names():
            if name in self.friction.table_names():
                continue  # the law checks its own table
            shape = np.shape(getattr(self.friction, name))
            if shape not in ((), (n,)):
                raise ValidationError(_shape_message(f"{type(self.friction).__name__}.{name}",
                                                     shape, ((), (n,))))


def chain_or_default(params: ChainParams | None, **defaults) -> ChainParams:
    """`params`, or when it is None the chain `ChainParams(**defaults)` (the paper's
    ring by default), built on call rather than as a default argument: a chain's
    arrays need `configure` (float64) first.

    **Raises:**

    `ValidationError` for defaults that `ChainParams` refuses.
    """
    return ChainParams(**defaults) if params is None else params


def _shape_message(name, shape, shapes) -> str:
    allowed = " or ".join(str(s) for s in shapes)
    hint = ("" if len(shapes) > 1 or shape == () else
            "; a batch of chains (one value per lane) is made by lane_params or "
            "stack_chains, not by a longer axis")
    return f"{name} must have shape {allowed}, got {shape}{hint}"


def single_oscillator(params: ChainParams, index: int = 0) -> ChainParams:
    """Oscillator `index` of the chain on its own: n_osc = 1 on the ring (no
    coupling), with that oscillator's xi, stiffness, load, friction law and force,
    the chain's v_d. The single oscillator of Fig. 3(a) for the paper's ring.
    Traceable in the parameters' values (`jax.jacfwd` through it).

    **Raises:**

    `ValidationError` for an index outside [0, n_osc).
    """
    if not 0 <= index < params.n_osc:
        raise ValidationError(f"index must lie in [0, {params.n_osc}), got {index!r}")

    def pick(value):  # traceable: for derivatives with respect to the chain
        return value if jnp.ndim(value) == 0 else jnp.asarray(value)[index]

    law = params.friction
    tables = law.table_names()
    law = eqx.tree_at(lambda f: [getattr(f, n) for n in law.parameter_names()], law,
                      [getattr(law, n) if n in tables else pick(getattr(law, n))
                       for n in law.parameter_names()])
    forcing = params.forcing
    if forcing is not None:
        forcing = Forcing(amplitude=pick(forcing.amplitude), frequency=forcing.frequency,
                          phase=pick(forcing.phase))
    return ChainParams(n_osc=1, xi=pick(params.xi), eta_c=params.eta_c if np.ndim(
        params.eta_c) == 0 else 0.0, v_d=params.v_d,
        stiffness=pick(params.stiffness), load=pick(params.load), friction=law,
        mass=None if params.mass is None else pick(params.mass), forcing=forcing)


def _chain_fields() -> list[str]:
    return [f.name for f in dataclasses.fields(ChainParams)
            if f.name not in ("n_osc", "friction", "forcing", "graph", "mistuning", "scales")]

#: The names of a `Forcing`'s fields among the parameters (`parameter_names`).
FORCING_NAMES = ("forcing.amplitude", "forcing.frequency", "forcing.phase")


def parameter_names(params: ChainParams | None = None) -> list[str]:
    """The names `with_parameter` and the sweeps take: the array fields of
    `ChainParams`, those of its friction law (`mu_st`, `mu_d`, `v0` for eq. (1)) and,
    for a forced chain, those of its `Forcing` ("forcing.frequency", ...).
    """
    law = ExponentialDecay if params is None else type(params.friction)
    forced = params is not None and params.forcing is not None
    return _chain_fields() + list(law.parameter_names()) + list(FORCING_NAMES if forced else ())


class _Field(eqx.Module):
    """The lens of one named field, of `ChainParams` or of its friction law: equal
    names compare and hash equal, so that a jitted function taking the lens
    compiles once per name."""

    name: str = eqx.field(static=True)

    def __call__(self, params):
        if self.name in _chain_fields():
            return getattr(params, self.name)
        if self.name in FORCING_NAMES:
            return getattr(params.forcing, self.name.removeprefix("forcing."))
        return getattr(params.friction, self.name)


def parameter_lens(where: Callable | str, params: ChainParams | None = None) -> Callable:
    """The lens of a parameter given by name (`"xi"`, or a field of the friction law
    such as `"mu_st"`) or already as a lens.

    **Raises:**

    `ValidationError` for an unknown name (for `params`' friction law, eq. (1) if None).
    """
    if not isinstance(where, str):
        return where
    names = parameter_names(params)
    if where == "eps":
        raise ValidationError(EPS_MOVED)
    if where not in names:
        raise ValidationError(f"unknown parameter {where!r}: choose one of {', '.join(names)}")
    return _Field(where)


def parameter_name(where: Callable | str, params: ChainParams | None = None) -> str:
    """The name of the one field that `where` picks: `where` itself when it is a
    name, or else found by applying the lens to parameters whose fields hold
    distinct values. A sweep keys and labels its results by this name, never by
    the lens (two lambdas cannot be compared by content).

    **Arguments:**

    - `where`: a field name such as `"eta_c"` or `"mu_st"`, or a lens such as
        `lambda p: p.eta_c` or `lambda p: p.friction.mu_st`.
    - `params`: the chain whose friction law the lens reads (eq. (1) if None).

    **Returns:**

    The field name.

    **Raises:**

    `ValidationError` for an unknown name, for n_osc (it sets the shapes: it cannot vary
    within one compiled run), or for a lens that does not return one field.
    """
    if isinstance(where, str):
        parameter_lens(where, params)  # raises for an unknown name
        return where
    base = chain_or_default(params)
    leaves, treedef = jax.tree_util.tree_flatten(base)
    probe = jax.tree_util.tree_unflatten(
        treedef, [np.asarray(0.125 * (i + 1)) for i in range(len(leaves))])
    try:
        picked = where(probe)
    except Exception as err:
        raise ValidationError(f"where must pick one field of ChainParams, got a lens that "
                              f"raised {type(err).__name__}: {err}") from None
    if picked is probe.n_osc and isinstance(picked, int):
        raise ValidationError("n_osc cannot be swept: it sets the shapes of a compiled run; "
                              "run one sweep per n_osc")
    for name in parameter_names(base):
        if picked is _Field(name)(probe):
            return name
    raise ValidationError(f"where must pick one field of ChainParams "
                          f"({', '.join(parameter_names(base))}), got a lens that returns "
                          f"{picked!r}")


def parameter_value(params: ChainParams, where: Callable | str):
    """The value of the parameter `where` (a name or a lens) in `params`."""
    return parameter_lens(where, params)(params)


def with_fields(params: ChainParams, **changes) -> ChainParams:
    """`params` with the named fields of `ChainParams` replaced, built and validated
    as a new `ChainParams`: the one route for a change of structure (n_osc, the
    graph or a line's `boundary`, a field's shape, the mistuning record; a new n_osc
    of a line keeps its boundary); `with_parameter` changes one
    value.

    **Raises:**

    `ValidationError` naming an unknown field, or the field of a bad value.
    """
    fields = {f.name: getattr(params, f.name) for f in dataclasses.fields(params)}
    unknown = sorted(set(changes) - set(fields) - {"boundary"})
    if unknown:
        raise ValidationError(f"ChainParams has no field {unknown[0]!r}; its fields are "
                              f"{', '.join(fields)}")
    fields |= changes
    if "graph" not in changes and ("boundary" in changes or (
            "n_osc" in changes and params.graph.is_line)):
        fields["graph"] = as_graph(fields.pop("boundary", params.boundary), fields["n_osc"])
    return ChainParams(**fields)


def with_parameter(params: ChainParams, where: Callable | str, value) -> ChainParams:
    """`params` with one parameter set to `value`, validated like a new `ChainParams`.
    This is the one way jaxchain changes a parameter (a bare `eqx.tree_at` would skip
    the validation and could leave a Python float, which `eqx.filter_jit` treats as
    static).

    **Arguments:**

    - `params`: the chain parameters.
    - `where`: the field, as a lens such as `lambda p: p.v_d` (as `eqx.tree_at`
        takes it) or as its name, `"v_d"` (or a friction law's field, `"mu_st"`).
    - `value`: the new value: a number, an array of the field's allowed shape, or a
        tracer.

    **Returns:**

    A new `ChainParams`.

    **Raises:**

    `ValidationError` naming the field for a bad value or shape, or for an unknown name.
    """
    changed = eqx.tree_at(parameter_lens(where, params), params, value)
    return with_fields(changed, friction=revalidated(changed.friction),
                       forcing=None if changed.forcing is None else revalidated(changed.forcing))


def revalidated(law: eqx.Module) -> eqx.Module:
    """The law (or forcing) built again from its fields (static ones included), so
    that its checks run on values set by `eqx.tree_at`."""
    return type(law)(**{f.name: getattr(law, f.name) for f in dataclasses.fields(law)})


def without_records(params: ChainParams) -> ChainParams:
    """`params` without its records (`mistuning`, `scales`), which say where its
    values came from and which no equation reads: the chain that a compiled program
    takes. A record is static, part of a program's key, so each mistuning draw (its
    seed) or system of units would otherwise compile the same program again."""
    if params.mistuning is None and params.scales is None:
        return params
    return with_fields(params, mistuning=None, scales=None)


def stack_chains(chains: list[ChainParams]) -> ChainParams:
    """A batch of chains, the named route to an ensemble over chains (for example
    100 mistuning draws): every array field gains a leading lane axis, shape
    (lanes, ...); a field that is a scalar in some chains and per-oscillator in
    others is broadcast to (lanes, n_osc). The chains must share n_osc, the
    graph, the class of the friction law and whether masses are given; their mistuning records are
    dropped (each lane's stiffness is kept). `run_lanes` takes the result.

    **Raises:**

    `ValidationError` for an empty list or chains of different structure.
    """
    if not chains:
        raise ValidationError("stack_chains needs at least one chain")
    plain = [with_fields(c, mistuning=None) for c in chains]
    structures = {jax.tree_util.tree_structure(c) for c in plain}
    if len(structures) != 1:
        raise ValidationError("stack_chains needs chains of one structure (n_osc, graph, "
                              "friction law, masses or none)")

    def stack(*xs):
        shape = np.broadcast_shapes(*(np.shape(x) for x in xs))
        return np.stack([np.broadcast_to(np.asarray(x, dtype=float), shape) for x in xs])

    return jax.tree_util.tree_map(stack, *plain)


def is_homogeneous_ring(params: ChainParams) -> bool:
    """Whether the chain is the paper's homogeneous ring: boundary "ring" and every
    per-oscillator or per-link field a scalar (a lane-batched `ChainParams` counts
    by its fields' trailing shape). Then the Jacobian at steady sliding is
    block-circulant (the Fourier route of `mode_eigenvalues`)."""
    if params.boundary != "ring" or params.mass is not None:
        return False
    return all(np.ndim(leaf) == 0 for leaf in _per_oscillator_leaves(params))


def _per_oscillator_leaves(params: ChainParams) -> list:
    """The fields that may hold one value per oscillator or per link: stiffness,
    load, xi, eta_c, mass (unless None) and the friction law's parameters."""
    mass = [] if params.mass is None else [params.mass]
    law = params.friction
    return ([params.stiffness, params.load, params.xi, params.eta_c] + mass
            + [getattr(law, n) for n in law.parameter_names() if n not in law.table_names()])
