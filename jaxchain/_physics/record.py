"""The whole chain as plain data (numbers, lists and strings), for results (netCDF,
zarr and JSON attributes) and chain files, and back."""

import dataclasses

import numpy as np

from .chain import Graph
from .forcing import Forcing
from .mistuning import Mistuning
from .scales import Scales
from .friction import FRICTION_LAWS
from .params import EPS_MOVED, ChainParams, _chain_fields
from .._errors import ValidationError

#: The keys of a forcing (`Forcing`) in a record; a chain file may give
#: `force_engine_order` r instead of `force_phase` (`Forcing.engine_order`).
FORCE_KEYS = ("force_amplitude", "force_frequency", "force_phase")

#: Keys of a record besides the array fields and the law's parameters.
_META = ("n_osc", "boundary", "lattice", "links", "friction", "mistuning_sigma",
         "mistuning_seed") + FORCE_KEYS + ("force_engine_order",) + tuple(
             Scales.of(1.0, 1.0, 1.0).record())


def _plain(value):
    a = np.asarray(value, dtype=float)
    return a.item() if a.ndim == 0 else a.tolist()


def _law_names(law) -> list[str]:
    """Every field of a friction law (class or instance), static ones included (the
    speeds of a `Tabulated` law): what rebuilds it."""
    return [f.name for f in dataclasses.fields(law)]


def _graph_record(graph: Graph) -> dict:
    """The graph as plain data: `boundary` (a line's name; for a lattice one name,
    or "ACROSS,ALONG" when its directions differ; "links" otherwise), with
    `lattice` = [rows, cols] or `links` = [left_0, right_0, left_1, ...] (0-based,
    -1 the ground)."""
    if graph.is_line:
        return {"boundary": graph.kind}
    if graph.kind == "lattice":
        b = graph.boundary
        return {"lattice": list(graph.shape), "boundary": b[0] if b[0] == b[1] else ",".join(b)}
    return {"boundary": "links", "links": [int(e) for link in graph.links for e in link]}


def _graph_from_record(record: dict, n_osc: int) -> Graph:
    """The graph of a record's `boundary`, `lattice` and `links` (`_graph_record`;
    a chain file may also give `links` as a list of pairs).

    **Raises:** `ValidationError` for a lattice that is not two sizes or whose size is
    not n_osc, links that are not pairs, or an unknown boundary."""
    boundary = record.get("boundary", "ring")
    if "lattice" in record:
        size = record["lattice"]
        if isinstance(size, str):
            size = size.lower().split("x")
        try:
            rows, cols = (int(v) for v in size)
        except (TypeError, ValueError):
            raise ValidationError(f"lattice must be [rows, cols] or \"ROWSxCOLS\", got "
                                  f"{record['lattice']!r}") from None
        names = tuple(boundary.split(",")) if "," in boundary else boundary
        graph = Graph.lattice(rows, cols, names)
    elif "links" in record or boundary == "links":
        flat = np.asarray(record.get("links", []))
        pairs = flat.reshape(-1, 2) if flat.ndim == 1 and flat.size % 2 == 0 else flat
        if pairs.ndim != 2 or pairs.shape[1] != 2:
            raise ValidationError(f"links must be pairs [left, right], got {record['links']!r}")
        graph = Graph.from_links(n_osc, pairs.tolist())
    else:
        graph = Graph.line(n_osc, boundary)
    if graph.n_osc != n_osc:
        raise ValidationError(f"n_osc is {n_osc} but the lattice has {graph.n_osc} oscillators")
    return graph


def chain_record(params: ChainParams) -> dict:
    """Every setting of the chain as flat plain data: `n_osc`, the graph
    (`boundary`, with `lattice` or `links`), `friction` (the law's name in
    `FRICTION_LAWS`), each array field of `ChainParams` (`mass` only when given) and
    each field of the law by name (a number, or a list of one value per oscillator
    or link, or a table), `mistuning_sigma`, `mistuning_seed` when the stiffness
    was drawn by `mistune`, and `force_amplitude`, `force_frequency`, `force_phase`
    for a forced chain (`Forcing`).
    `chain_from_record` rebuilds the chain from it.

    **Raises:**

    `ValidationError` for a friction law that is not in `FRICTION_LAWS` (it could not
    be rebuilt by name). `check_recordable` raises it before a run.
    """
    law = type(params.friction)
    out = {"n_osc": params.n_osc} | _graph_record(params.graph)
    out["friction"] = check_recordable(params)
    out |= {name: _plain(getattr(params, name)) for name in _chain_fields()
            if getattr(params, name) is not None}
    out |= {name: _plain(getattr(params.friction, name)) for name in _law_names(law)}
    if params.forcing is not None:
        out |= {key: _plain(getattr(params.forcing, key.removeprefix("force_")))
                for key in FORCE_KEYS}
    if params.mistuning is not None:
        out |= {"mistuning_sigma": float(params.mistuning.sigma),
                "mistuning_seed": int(params.mistuning.seed)}
    if params.scales is not None:
        out |= params.scales.record()
    return out


def check_recordable(params: ChainParams) -> str:
    """The name (in `FRICTION_LAWS`) under which the chain's friction law is
    recorded. Studies call it before they run, so that a law that cannot be
    recorded is refused before the work, not after.

    **Raises:**

    `ValidationError` naming the law's class and the named laws when it is not one.
    """
    names = {cls: name for name, cls in FRICTION_LAWS.items()}
    law = type(params.friction)
    if law not in names:
        raise ValidationError(f"a chain with the friction law {law.__name__} cannot be recorded "
                              f"in results (by name); the named laws are "
                              f"{', '.join(FRICTION_LAWS)}: use one of them, or jaxchain."
                              f"Tabulated(v, mu) sampled from yours")
    return names[law]


def _chain_settings(mapping: dict) -> list[str]:
    """The keys of `mapping` (for example a Dataset's attributes) that belong to the
    chain's record (`chain_record`), for the friction law it names."""
    law = FRICTION_LAWS.get(mapping.get("friction"), FRICTION_LAWS["exponential"])
    keys = set(_META) | set(_chain_fields()) | set(_law_names(law))
    return [k for k in mapping if k in keys]


def chain_from_record(record: dict, base: ChainParams | None = None) -> ChainParams:
    """The chain of a record (`chain_record`, or a chain file's table): keys that
    are absent keep their value in `base` (the defaults if None); a `friction`
    name without its parameters takes that law's defaults. With
    `mistuning_sigma`, the stiffness is drawn again from the record (and must match
    a `stiffness` given beside it).

    **Raises:**

    `ValidationError` for an unknown key, law name or boundary, or a bad value (naming
    the field).
    """
    base = ChainParams() if base is None else base
    record = dict(record)
    unknown_law = record.get("friction", None)
    if unknown_law is not None and unknown_law not in FRICTION_LAWS:
        raise ValidationError(f"friction must be one of {', '.join(FRICTION_LAWS)}, "
                              f"got {unknown_law!r}")
    law = FRICTION_LAWS[record.pop("friction")] if "friction" in record else type(base.friction)
    names = _law_names(law)
    allowed = set(_META) | set(_chain_fields()) | set(names)
    unknown = sorted(set(record) - allowed)
    if unknown:
        raise ValidationError(f"unknown chain setting {unknown[0]!r}: the settings are "
                              f"{', '.join(sorted(allowed - {'friction'}))} and friction")
    if law is type(base.friction):
        law_values = {name: getattr(base.friction, name) for name in names}
    else:
        law_values = {}
    law_values |= {name: record.pop(name) for name in names if name in record}
    sigma, seed = record.pop("mistuning_sigma", None), record.pop("mistuning_seed", None)
    forcing = _forcing_from_record(record, record.get("n_osc", base.n_osc), base.forcing)
    scales = Scales.from_record(record)
    for key in Scales.of(1.0, 1.0, 1.0).record():
        record.pop(key, None)
    topology = {k: record.pop(k) for k in ("boundary", "lattice", "links") if k in record}
    fields = {name: getattr(base, name) for name in _chain_fields()}
    fields |= record
    if "n_osc" not in record and "lattice" in topology:
        size = topology["lattice"]
        size = size.lower().split("x") if isinstance(size, str) else size
        fields["n_osc"] = int(np.prod([int(v) for v in size]))
    n_osc = fields.setdefault("n_osc", base.n_osc)
    if topology:
        fields["graph"] = _graph_from_record(topology, n_osc)
    elif n_osc == base.n_osc:
        fields["graph"] = base.graph
    else:
        fields["boundary"] = base.boundary
    if sigma is not None:
        mistuning = Mistuning(sigma=sigma, seed=0 if seed is None else seed)
        drawn = base.stiffness if sigma == 0 else mistuning.stiffness(n_osc)
        if "stiffness" in record and not np.array_equal(
                np.broadcast_to(np.asarray(record["stiffness"], dtype=float), (n_osc,)),
                np.broadcast_to(drawn, (n_osc,))):
            raise ValidationError("stiffness is not the one mistuning_sigma and mistuning_seed "
                                  "draw; give one or the other")
        fields |= {"stiffness": drawn, "mistuning": mistuning}
    if scales is not None:
        fields["scales"] = scales
    return ChainParams(**fields, friction=law(**law_values), forcing=forcing)


def _forcing_from_record(record: dict, n_osc: int, base: Forcing | None) -> Forcing | None:
    """The `Forcing` of a record's `force_*` keys, popped from it (`base`, the
    chain's own, where it has none): amplitude and frequency, with `force_phase` or
    `force_engine_order` (r: phase 2 pi r n / N).

    **Raises:** `ValidationError` for a forcing without its amplitude or frequency,
    both a phase and an engine order, or a bad value (naming the field)."""
    given = {k: record.pop(k) for k in FORCE_KEYS + ("force_engine_order",) if k in record}
    if not given:
        return base
    missing = [k for k in FORCE_KEYS[:2] if k not in given]
    if missing:
        raise ValidationError(f"{missing[0]} is missing: a forcing takes force_amplitude and "
                              "force_frequency (with force_phase or force_engine_order)")
    if "force_engine_order" in given:
        if "force_phase" in given:
            raise ValidationError("give force_phase or force_engine_order, not both")
        return Forcing.engine_order(int(n_osc), given["force_engine_order"],
                                    given["force_amplitude"], given["force_frequency"])
    return Forcing(amplitude=given["force_amplitude"], frequency=given["force_frequency"],
                   phase=given.get("force_phase", 0.0))


def _read_chain_file(path) -> dict:
    """The settings of a TOML chain file, as a record for `chain_from_record`: n_osc,
    boundary, xi, eta_c (one value per link), stiffness, load (one value per
    oscillator), friction = "NAME" and the law's parameters.

    **Raises:**

    `ValidationError` naming the file when it cannot be read or is not valid TOML.
    """
    import tomllib

    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except OSError as err:
        raise ValidationError(f"{path}: cannot read it ({err.strerror})") from None
    except tomllib.TOMLDecodeError as err:
        raise ValidationError(f"{path}: not valid TOML ({err})") from None


#: The keys of a chain file in SI units (`units = "SI"`), read by `from_physical`.
SI_KEYS = ("mass", "stiffness", "damping", "normal_load", "coupling_stiffness",
           "belt_speed", "reference")


def chain_from_file(path, base: ChainParams | None = None) -> ChainParams:
    """The chain of a TOML chain file (the schema: documentation, "Chain files").

    A dimensionless file holds a record (`chain_from_record`: n_osc, boundary,
    lattice or links, xi, eta_c, stiffness, load, mass, friction and its
    parameters, ...). `table = "FILE.csv"` (relative to the chain file) gives a
    `Tabulated` law's v and mu. A file with `units = "SI"` holds instead the
    arguments of `from_physical` (mass, stiffness, damping, normal_load,
    coupling_stiffness, belt_speed; reference), the topology and the
    friction law with its velocities in m/s.

    **Raises:**

    `ValidationError` naming the file and the setting for a file that cannot be read,
    is not valid TOML, or holds a bad setting.
    """
    from pathlib import Path

    from .friction import Tabulated
    from .units import from_physical

    record = _read_chain_file(path)
    try:
        if "eps" in record:  # a chain holds physics only
            raise ValidationError(EPS_MOVED)
        if "table" in record:
            law = Tabulated.from_csv(Path(path).parent / str(record.pop("table")))
            record |= {"friction": "table", "v": list(law.v), "mu": law.mu.tolist()}
        units = record.pop("units", "dimensionless")
        if units == "dimensionless":
            return chain_from_record(record, base)
        if units != "SI":
            raise ValidationError(f"units must be \"SI\" or \"dimensionless\", got {units!r}")
        si = {k: record.pop(k) for k in SI_KEYS if k in record}
        law = FRICTION_LAWS[record.pop("friction", "exponential")]
        law = law(**{k: record.pop(k) for k in _law_names(law) if k in record})
        topology = {k: record.pop(k) for k in ("boundary", "lattice", "links") if k in record}
        n_osc = record.pop("n_osc", None)
        if record:
            raise ValidationError(f"unknown setting {sorted(record)[0]!r} of a chain in SI "
                                  f"units: the settings are {', '.join(SI_KEYS)}, n_osc, "
                                  "boundary, lattice, links, friction and its parameters")
        if "lattice" in topology or "links" in topology:
            size = topology.get("lattice")
            n = n_osc if size is None else int(np.prod(
                size.lower().split("x") if isinstance(size, str) else size, dtype=int))
            topology = {"graph": _graph_from_record(topology, int(n))}
        si.setdefault("belt_speed", 1.0)
        return from_physical(friction=law, n_osc=n_osc, **topology, **si)
    except (ValueError, TypeError) as err:
        raise ValidationError(f"{path}: {err}") from None
