"""The stress matrix as a Markdown table: one row per case, one column per solver
path, with the counts of each outcome."""

from collections import Counter


def counts(rows: list[dict]) -> dict[str, int]:
    """Runs tried, verified, failed with a specific status (the run's own `Status`,
    a hint attached) and failed otherwise (a physics check that did not hold, or
    a non-finite result reported as ok: defects)."""
    status = Counter(r["status"] for r in rows if r["outcome"] == "failed")
    defects = status["check failed"] + status["non-finite result"]
    return {"tried": len(rows), "verified": sum(r["outcome"] == "verified" for r in rows),
            "failed_with_status": sum(status.values()) - defects, "defects": defects}


def _value(value) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def _cell(row: dict) -> str:
    if row["outcome"] == "verified":
        return f"verified ({row['num_steps']} steps)"
    return f"**{row['status']}**"


def markdown(rows: list[dict]) -> str:
    """The rows of `stress` as a Markdown table (cases down, solvers across), then
    each failure with its hint, and each verified case's checks.

    **Returns:**

    Markdown text.
    """
    solvers = list(dict.fromkeys(r["solver"] for r in rows))
    cases = list(dict.fromkeys((r["what"], r["value"]) for r in rows))
    by = {(r["what"], r["value"], r["solver"]): r for r in rows}
    c = counts(rows)
    lines = [f"{c['tried']} runs: {c['verified']} verified, {c['failed_with_status']} "
             f"failed with a specific status, {c['defects']} defects (a physics check "
             "that did not hold, or a non-finite result reported as ok).", "",
             "| what varies | value | " + " | ".join(solvers) + " |",
             "| --- | --- | " + " | ".join("---" for _ in solvers) + " |"]
    for what, value in cases:
        cells = [_cell(by[what, value, s]) if (what, value, s) in by else "" for s in solvers]
        lines.append(f"| {what} | {_value(value)} | " + " | ".join(cells) + " |")
    failures = [r for r in rows if r["outcome"] == "failed"]
    if failures:
        lines += ["", "**Failures, with their hints:**", ""]
        lines += [f"- {r['what']} = {_value(r['value'])}, {r['solver']}: {r['status']}. "
                  f"{r['check'] or r['hint']}" for r in failures]
    lines += ["", "**Checks of the verified runs:**", ""]
    lines += [f"- {r['what']} = {_value(r['value'])}, {r['solver']}: {r['check']}"
              for r in rows if r["outcome"] == "verified"]
    return "\n".join(lines) + "\n"
