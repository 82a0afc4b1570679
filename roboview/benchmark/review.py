"""Stage-2 review: the decisions a reviewer (or a VLM screen) takes on gate results, read and applied.

A decisions CSV has columns instance_id, verdict (accept / reject), reviewer, note. A reviewer may
reject what the gate passed, or accept what it flagged; the card counts both.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

VERDICTS = ("accept", "reject")


@dataclass(frozen=True)
class Decision:
    instance_id: str
    verdict: str
    reviewer: str
    note: str


def read_decisions(path: Path, known_ids: set[str]) -> dict[str, Decision]:
    """Stage-2 adjudication CSV (instance_id, verdict, reviewer, note). A VLM screen writes the same
    file with reviewer "vlm:<model>"; every id must belong to the suite being built."""
    if not path.is_file():
        raise ValueError(f"decisions file {path} does not exist")
    with path.open(newline="") as f:
        reader = csv.DictReader(f)
        missing = {"instance_id", "verdict"} - set(reader.fieldnames or [])
        if missing:
            raise ValueError(
                f"decisions file {path} lacks column(s) {sorted(missing)}; "
                "expected: instance_id, verdict, reviewer, note"
            )
        rows = list(reader)
    unknown = sorted({r["instance_id"] for r in rows} - known_ids)
    if unknown:
        raise ValueError(
            f"decisions file {path} names {len(unknown)} instance id(s) not in this suite: "
            f"{', '.join(unknown[:5])}{' …' if len(unknown) > 5 else ''}"
        )
    bad = sorted({r["verdict"] for r in rows} - set(VERDICTS))
    if bad:
        raise ValueError(f"decisions file {path}: unknown verdict(s) {bad}; allowed: {', '.join(VERDICTS)}")
    return {
        r["instance_id"]: Decision(
            r["instance_id"], r["verdict"], r.get("reviewer") or "human", r.get("note") or ""
        )
        for r in rows
    }


def adjudicate(record: dict, decision: Decision | None, ungated: bool = False) -> tuple[bool, str]:
    """(accepted, rejected_by) after stage 1 (the gate) and stage 2 (a decision, if any); an `ungated` record (an
    external benchmark's own variant) passes stage 1 whatever the gate measured, its verdict kept in its record."""
    gate_passed = record["fairness"]["passed"] or ungated
    if decision is None:
        return gate_passed, "" if gate_passed else "gate"
    if decision.verdict == "reject":
        return False, f"{decision.reviewer}: {decision.note}".rstrip(": ")
    return True, ""  # a reviewer may accept what the gate flagged; the card counts these
