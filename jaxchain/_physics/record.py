"""The whole chain as plain data (numbers, lists and strings), for results (netCDF,
zarr and JSON attributes) and chain files, and back."""

import numpy as np

from .chain import Mistuning
from .friction import FRICTION_LAWS
from .params import ChainParams, _chain_fields
from .._errors import ValidationError

#: Keys of a record besides the array fields and the law's parameters.
_META = ("n_osc", "boundary", "friction", "mistuning_sigma", "mistuning_seed")


def _plain(value):
    a = np.asarray(value, dtype=float)
    return a.item() if a.ndim == 0 else a.tolist()


def chain_record(params: ChainParams) -> dict:
    """Every setting of the chain as flat plain data: `n_osc`, `boundary`,
    `friction` (the law's name in `FRICTION_LAWS`), each array field of
    `ChainParams` and each parameter of the law by name (a number, or a list of
    one value per oscillator or link), and `mistuning_sigma`, `mistuning_seed`
    when the stiffness was drawn by `mistune`. `chain_from_record` rebuilds the
    chain from it.

    **Raises:**

    `ValidationError` for a friction law that is not in `FRICTION_LAWS` (it could not
    be rebuilt by name).
    """
    names = {cls: name for name, cls in FRICTION_LAWS.items()}
    law = type(params.friction)
    if law not in names:
        raise ValidationError(f"a chain with the friction law {law.__name__} cannot be recorded "
                              f"by name; the named laws are {', '.join(FRICTION_LAWS)}")
    out = {"n_osc": params.n_osc, "boundary": params.boundary, "friction": names[law]}
    out |= {name: _plain(getattr(params, name)) for name in _chain_fields()}
    out |= {name: _plain(getattr(params.friction, name)) for name in law.parameter_names()}
    if params.mistuning is not None:
        out |= {"mistuning_sigma": float(params.mistuning.sigma),
                "mistuning_seed": int(params.mistuning.seed)}
    return out


def chain_settings(mapping: dict) -> list[str]:
    """The keys of `mapping` (for example a Dataset's attributes) that belong to the
    chain's record (`chain_record`), for the friction law it names."""
    law = FRICTION_LAWS.get(mapping.get("friction"), FRICTION_LAWS["exponential"])
    keys = set(_META) | set(_chain_fields()) | set(law.parameter_names())
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
    law_names = law.parameter_names()
    allowed = set(_META) | set(_chain_fields()) | set(law_names)
    unknown = sorted(set(record) - allowed)
    if unknown:
        raise ValidationError(f"unknown chain setting {unknown[0]!r}: the settings are "
                              f"{', '.join(sorted(allowed - {'friction'}))} and friction")
    if law is type(base.friction):
        law_values = {name: getattr(base.friction, name) for name in law_names}
    else:
        law_values = {}
    law_values |= {name: record.pop(name) for name in law_names if name in record}
    sigma, seed = record.pop("mistuning_sigma", None), record.pop("mistuning_seed", None)
    fields = {name: getattr(base, name) for name in _chain_fields()}
    fields |= {"n_osc": base.n_osc, "boundary": base.boundary}
    fields |= record
    n_osc = fields["n_osc"]
    if sigma is not None:
        mistuning = Mistuning(sigma=sigma, seed=0 if seed is None else seed)
        drawn = base.stiffness if sigma == 0 else mistuning.stiffness(n_osc)
        if "stiffness" in record and not np.array_equal(
                np.broadcast_to(np.asarray(record["stiffness"], dtype=float), (n_osc,)),
                np.broadcast_to(drawn, (n_osc,))):
            raise ValidationError("stiffness is not the one mistuning_sigma and mistuning_seed "
                                  "draw; give one or the other")
        fields |= {"stiffness": drawn, "mistuning": mistuning}
    return ChainParams(**fields, friction=law(**law_values))


def read_chain_file(path) -> dict:
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
