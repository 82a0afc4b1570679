"""Stage 1b: the paper's VLM fairness screen, and how far it agrees with the programmatic gate.

Each candidate's `front` image at t = 0 goes to a VLM with the appendix prompt (a small solid
object? a yellow box? both clearly identifiable?). The answer — yes / no and the model's analysis —
is stored in the instance's fairness record. The screen never rejects anything by itself: the build
reports its pass rate against the paper's ≥ 95 % loop criterion, its agreement with the gate
(Cohen's κ, statsmodels) and every disagreement, and writes the answers as a decisions file
(`vlm_screen.csv`, reviewer `vlm:<model>`) that a reviewer may pass to the next build with
`--decisions` once they have looked at the disagreements in the contact sheet.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

import numpy as np
from statsmodels.stats.inter_rater import cohens_kappa

SCREEN_CAMERA = "front"
PAPER_TARGET = 0.95
ANSWERS = ("yes", "no")

# The paper's appendix prompt (GPT-4o screen), verbatim.
FAIRNESS_SCREEN = """You are an expert image analyst acting as aJSON API. Your task is to analyze the provided image and return a single, valid JSON object. Do not output any text before or after the JSON object.
**1. Conditions to Check:**
- Is there a small solid geometry object in the image?
- Is there a yellow box in the image?
- Can a person clearly identify both the geometry object and the yellow box?

**2. Rule for the Final Answer:**
- If ALL THREE conditions are true, the `final_answer` value is "yes".
- If ANY condition is false, the `final_answer` value is "no".

**3. Required JSON Output Format:**
Your entire output must be a single JSON object with these two keys:
- `analysis`: A string containing a brief explanation of your reasoning.
- `final_answer`: A string that is either "yes" or "no".
---
**Example 1 (All conditions met):**
{
  "analysis": "The image clearly shows a small blue pyramid and a yellow box, and both are identifiable.",
  "final_answer": "yes"
}
**Example 2 (One condition fails):**
{
  "analysis": "The image contains a small pyramid, but the box is red, not yellow.",
  "final_answer": "no"
}
---
Now, analyze the image I provide and respond only with a valid JSON object as specified."""


def check_answer(answer: Any) -> tuple[str, str]:
    """(final_answer, analysis) from the screen's JSON; anything else raises ValueError."""
    if not isinstance(answer, dict):
        raise ValueError("expected a JSON object with analysis and final_answer")
    final = str(answer.get("final_answer", "")).strip().lower()
    if final not in ANSWERS:
        raise ValueError(f'final_answer must be "yes" or "no", got {answer.get("final_answer")!r}')
    return final, str(answer.get("analysis", ""))


def screen_image(client: Any, prompt: str, image: np.ndarray) -> dict[str, str]:
    """One instance's screen: {"answer": yes | no | error, "analysis": ...}; errors are recorded, not raised."""
    try:
        final, analysis = client.ask_json(prompt, [image], check_answer)
    except Exception as exc:  # noqa: BLE001 - a screen failure must not stop the build
        return {"answer": "error", "analysis": f"{type(exc).__name__}: {exc}"}
    return {"answer": final, "analysis": analysis}


def agreement(records: list[dict]) -> dict[str, Any]:
    """Screen pass rate, the 2×2 table against the gate, Cohen's κ and the disagreeing instances."""
    screened = [r for r in records if r["fairness"]["vlm_answer"] in ANSWERS]
    table = np.zeros((2, 2), dtype=int)  # rows: gate pass / fail; columns: VLM yes / no
    disagree = []
    for r in screened:
        gate, vlm = r["fairness"]["passed"], r["fairness"]["vlm_answer"] == "yes"
        table[0 if gate else 1, 0 if vlm else 1] += 1
        if gate != vlm:
            disagree.append(
                {
                    "instance_id": r["instance_id"],
                    "split": r["split"],
                    "value": r["value"],
                    "gate": "pass" if gate else "fail",
                    "vlm": r["fairness"]["vlm_answer"],
                    "analysis": r["fairness"]["vlm_analysis"],
                }
            )
    n = int(table.sum())
    observed = (table[0, 0] + table[1, 1]) / n if n else math.nan
    kappa = float(cohens_kappa(table, return_results=False)) if n and _informative(table) else None
    pass_rate = float(table[:, 0].sum() / n) if n else math.nan
    return {
        "screened": n,
        "errors": len(records) - n,
        "pass_rate": round(pass_rate, 4),
        "meets_paper_target": bool(pass_rate >= PAPER_TARGET) if n else False,
        "table": {
            "gate_pass_vlm_yes": int(table[0, 0]),
            "gate_pass_vlm_no": int(table[0, 1]),
            "gate_fail_vlm_yes": int(table[1, 0]),
            "gate_fail_vlm_no": int(table[1, 1]),
        },
        "observed_agreement": round(float(observed), 4),
        "cohens_kappa": None if kappa is None else round(kappa, 4),
        "disagreements": disagree,
    }


def _informative(table: np.ndarray) -> bool:
    # κ is undefined when either rater gives one answer to everything (expected agreement = 1).
    return bool(table.sum(axis=0).min() > 0 or table.sum(axis=1).min() > 0) and not (
        (table.sum(axis=0) == table.sum()).any() and (table.sum(axis=1) == table.sum()).any()
    )


def write_decisions(path: Path, records: list[dict], reviewer: str) -> None:
    """The screen's answers as a stage-2 decisions file (accept / reject, reviewer vlm:<model>)."""
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["instance_id", "verdict", "reviewer", "note"])
        for r in records:
            answer = r["fairness"]["vlm_answer"]
            if answer in ANSWERS:
                writer.writerow(
                    [
                        r["instance_id"],
                        "accept" if answer == "yes" else "reject",
                        reviewer,
                        r["fairness"]["vlm_analysis"],
                    ]
                )
