"""Chain files written: a chain as TOML, read back by `chain_from_file`."""

from pathlib import Path

from .atomic import write_text
from .._physics.params import ChainParams
from .._physics.record import chain_record


def write_chain_file(params: ChainParams, path: str | Path) -> Path:
    """Write the chain as a TOML chain file: its record (`chain_record`) in
    dimensionless units, with its scales if it has them, written to a temporary name
    and renamed into place. `chain_from_file` reads back the same chain.

    **Returns:** the path written.

    **Raises:** `ValidationError` for a law that cannot be recorded."""
    import tomli_w

    record = chain_record(params)
    if "links" in record:
        flat = record["links"]
        record["links"] = [flat[i:i + 2] for i in range(0, len(flat), 2)]
    return write_text(path, "# jaxchain chain file (dimensionless, eqs. (4)-(6) of the "
                      "paper)\n" + tomli_w.dumps(record))
