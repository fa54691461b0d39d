"""Model choice between friction laws: each law fitted to the same records and
judged on records held out from its fit."""

from __future__ import annotations

import numpy as np

from ..._errors import ValidationError
from ..._physics.friction import FRICTION_LAWS, Tabulated
from ..._physics.params import ChainParams, with_fields
from .fit import IdentifyOptions, held_out_rms, identify


def _law_chain(chain: ChainParams, law: str) -> ChainParams:
    """`chain` with the friction law named `law` (of `FRICTION_LAWS`) at its
    defaults; the chain's own law if it is that law already (a table keeps its
    speeds).

    **Raises:** `ValidationError` for an unknown law, or a table law for a chain
    without a table (its speeds are the user's)."""
    if law not in FRICTION_LAWS:
        raise ValidationError(f"laws: unknown friction law {law!r}: choose from "
                              f"{', '.join(FRICTION_LAWS)}")
    cls = FRICTION_LAWS[law]
    if isinstance(chain.friction, cls):
        return chain
    if cls is Tabulated:
        raise ValidationError("laws: a table law needs the table's speeds: give the "
                              "chain a table (--friction table:FILE.csv)")
    return with_fields(chain, friction=cls())


def compare_laws(records, held_out, chain: ChainParams, laws, *, fit_chain=("xi",),
                 offsets: bool = False,
                 options: IdentifyOptions = IdentifyOptions()) -> list[dict]:
    """Fit each friction law in `laws` to `records` and judge it on `held_out`, the
    records it was not fitted to.

    Each law fits all its parameters and the chain's parameters `fit_chain`. On a
    held-out record only the windows' states (and offsets) are fitted, with the
    law's parameters fixed: the held-out residual measures how well the law
    predicts motion it has not seen (`held_out_rms`; with held-out records of the
    fitted ones' lengths it reuses the fit's compiled program), which an
    information criterion on the fitted records estimates (Burnham & Anderson,
    *Model Selection and Multimodel Inference*, 2nd ed. (2002), Ch. 2).

    **Arguments:**

    - `records`, `held_out`: lists of `Record`s (held_out may not be empty).
    - `chain`: the chain; its law is replaced by each law in turn.
    - `laws`: names of `FRICTION_LAWS`.
    - `fit_chain`, `offsets`, `options`: as in `identify`.

    **Returns:**

    One dict per law, in the order given: `law`, `fit` (its `Identification`),
    `sigma`, `aic`, `bic` (on `records`), `held_out_rms` (the root mean square
    residual on `held_out`), `best` (the lowest held-out residual).

    **Raises:** `ValidationError` for no law, no held-out record, or a bad law.
    """
    if not laws:
        raise ValidationError("laws: name at least one friction law")
    if not held_out:
        raise ValidationError("model choice needs at least one held-out record")
    rows = []
    for law in laws:
        trial = _law_chain(chain, law)
        names = tuple(type(trial.friction).parameter_names()) + tuple(fit_chain)
        fit = identify(records, trial, names, offsets=offsets, options=options)
        rows.append({"law": law, "fit": fit, "sigma": fit.sigma, "aic": fit.aic,
                     "bic": fit.bic, "held_out_rms": held_out_rms(
                         held_out, fit, offsets=offsets, options=options)})
    best = int(np.argmin([r["held_out_rms"] for r in rows]))
    for i, row in enumerate(rows):
        row["best"] = i == best
    return rows
