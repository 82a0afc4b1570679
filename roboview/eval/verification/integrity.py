"""What a results folder's own files must agree on before its numbers mean anything: the episode table against the
row's declared schema (roboview.eval.running.row.SCHEMA), each row plausible, run.json against what the rows and
provenance.json record of the same run, and every row's conformance verdict re-derived from provenance.json against
the benchmark's stack, never taken from the row."""

from __future__ import annotations

import re
from collections import Counter
from pathlib import Path

import pyarrow as pa

from roboview.eval.running.row import ALLOWED, INFRA_ERROR, SCHEMA, STATUS, STATUS_OK
from roboview.eval.verification.report import Check, listed

_KINDS = {
    "string": (pa.types.is_string, pa.types.is_large_string),
    "integer": (pa.types.is_integer,),
    "bool": (pa.types.is_boolean,),
    "float": (pa.types.is_floating, pa.types.is_integer),
}
# A timeout's failure reason names the step budget: roboview.tasks.base.Task.timeout_failure.
_TIMEOUT = re.compile(r"within (\d+) steps$")
# A stack whose MuJoCo or physics options differ from the benchmark's is not taken as `identical` on its word (every
# MuJoCo upgrade measured so far changed the reference images or rollouts).
_SIMULATION = ("mujoco", "physics option")


def check_schema(table: pa.Table) -> Check:
    """Every declared column present with its kind, no null where none is allowed, every status and
    conformance value an allowed one."""
    problems = []
    for name, (kind, nullable) in SCHEMA.items():
        if name not in table.column_names:
            problems.append(f"no `{name}` column")
            continue
        column = table.column(name)
        if not any(test(column.type) for test in _KINDS[kind]):
            problems.append(f"`{name}` is {column.type}, not {kind}")
        elif not nullable and column.null_count:
            problems.append(f"`{name}` is null in {column.null_count} rows")
    for name, allowed in ALLOWED.items():
        if name in table.column_names:
            bad = sorted({str(v) for v in table.column(name).to_pylist()} - set(allowed))
            if bad:
                problems.append(f"`{name}` holds {bad}; allowed: {', '.join(allowed)}")
    return Check(
        "schema",
        not problems,
        "; ".join(problems) if problems else f"{table.num_rows} rows, every declared column of its kind",
    )


def check_plausible(rows: list[dict], max_steps: int | None) -> Check:
    """Outcomes that cannot happen: a success with a failure reason or no step, a timeout before its step budget,
    more steps than the run's budget."""
    odd = []
    for r in rows:
        where = f"{r['instance_id']} repeat {r['repeat']}"
        steps, reason = r.get("steps"), r.get("failure_reason") or ""
        timeout = _TIMEOUT.search(reason)
        if r["success"] and reason:
            odd.append(f"{where}: a success with failure reason {reason!r}")
        elif r["success"] and r.get(STATUS) == STATUS_OK and steps is not None and steps < 1:
            odd.append(f"{where}: a success in {steps} steps")
        elif timeout and steps is not None and steps < int(timeout.group(1)):
            odd.append(f"{where}: a timeout within {timeout.group(1)} steps after {steps}")
        elif max_steps and steps is not None and steps > max_steps:
            odd.append(f"{where}: {steps} steps, beyond the run's budget of {max_steps}")
    return Check(
        "plausible",
        not odd,
        f"{len(odd)} rows record what cannot happen: {listed(odd)}" if odd else "every outcome possible",
    )


def check_conformance(rows: list[dict], results: Path, bench_stack: dict | None) -> Check:
    """Each run's verdict re-derived: its recorded stack against the benchmark's (an `identical` verdict with a
    simulation that differs, or stack differences that are not the recorded ones, fail), no run `different`, and
    every row's verdict one that a run of this folder recorded."""
    from roboview.eval.running import provenance
    from roboview.sim import stack

    entries = [e["conformance"] for e in provenance.read(results) if e.get("conformance")]
    verdicts = Counter(r.get("conformance") or "not recorded" for r in rows)
    problems = []
    if rows and not entries:
        problems.append("no run recorded its stack in provenance.json")
    for i, entry in enumerate(entries):
        derived = stack.differences(bench_stack, entry.get("stack"))
        if sorted(derived) != sorted(entry.get("stack_differences") or []):
            problems.append(
                f"run {i}: its stack differs from the benchmark's in {derived or 'nothing'}, not as recorded"
            )
        if entry.get("verdict") == "identical" and any(d.startswith(_SIMULATION) for d in derived):
            problems.append(f"run {i}: `identical` on another simulation ({'; '.join(derived)})")
        if entry.get("verdict") not in ("identical", "equivalent"):
            problems.append(f"run {i} ran on a stack whose conformance is {entry.get('verdict')!r}")
    recorded = {e.get("verdict") for e in entries}
    unbacked = sorted(v for v in verdicts if v not in recorded)
    if unbacked:
        problems.append(
            f"rows labelled {unbacked}, a verdict no run of this folder recorded ({sorted(recorded)})"
        )
    tally = ", ".join(f"{n} rows {v}" for v, n in sorted(verdicts.items()))
    return Check(
        "conformance",
        not problems,
        f"{tally}; {len(entries)} run(s), each verdict re-derived from its stack"
        if not problems
        else f"{tally} — " + "; ".join(problems),
    )


def check_record(rows: list[dict], run: dict, table_policy: str | None, entries: list[dict]) -> Check:
    """run.json against what the folder's other files record of the same run: the rows' `policy` column (run.json's
    policy_name, else the name its policy type gives its rows), the table's own policy, and the control, image size
    and step budget each run's provenance entry records, the budget also against the rows' timeouts."""
    from fnmatch import fnmatchcase

    from roboview.eval.running.results import RUN_DEFAULTS
    from roboview.policies.types import row_name_pattern

    kind = str(run.get("policy") or "")
    counted = [r for r in rows if r.get(STATUS) != INFRA_ERROR]
    expected = run.get("policy_name") or row_name_pattern(kind, run.get("policy_options") or {})
    names = Counter(str(r.get("policy")) for r in counted)
    problems = [
        f"{n} rows name policy {name!r}, run.json's policy {kind!r} names its rows {expected!r}"
        for name, n in sorted(names.items())
        if not fnmatchcase(name, expected)
    ]
    if table_policy is not None and table_policy != kind:
        problems.append(f"episodes.parquet records policy {table_policy!r}, run.json {kind!r}")
    for key, label in (("control", "control"), ("image_size", "image size"), ("max_steps", "max steps")):
        mine = run.get(key, RUN_DEFAULTS.get(key))
        theirs = sorted({str(e[key]) for e in entries if key in e and e[key] != mine})
        if theirs:
            problems.append(
                f"run.json's {label} is {mine}, a run in provenance.json ran with {', '.join(theirs)}"
            )
    budget = run.get("max_steps")
    timeouts = sorted(
        {int(m.group(1)) for r in counted if (m := _TIMEOUT.search(r.get("failure_reason") or ""))}
    )
    if budget is not None and any(t != budget for t in timeouts):
        problems.append(
            f"run.json's max steps is {budget}, the rows time out within {listed(timeouts)} steps"
        )
    return Check(
        "record",
        not problems,
        "; ".join(problems)
        if problems
        else f"run.json, the rows and provenance agree: policy {kind} ({', '.join(sorted(names)) or 'no rows'}), "
        f"control {run.get('control', RUN_DEFAULTS['control'])}, image size {run.get('image_size')}, "
        f"max steps {budget}",
    )
