"""Stage-2 review aid: a static HTML contact sheet of every candidate instance.

One card per instance: preview (front | left_top | wrist at t = 0), id, factor values, the measured
fairness numbers and the gate's verdict; filterable by split and by verdict. Reviewers write their
verdicts into a decisions CSV (instance_id, verdict, reviewer, note) read back by the next build.
"""

from __future__ import annotations

import html
from pathlib import Path

from roboview.variation.factors import DEFAULT_TASK, context_factors

PAGE = """<!doctype html>
<html><head><meta charset="utf-8"><title>RoboView contact sheet</title>
<style>
body {{ font-family: sans-serif; margin: 1em; }}
.grid {{ display: flex; flex-wrap: wrap; gap: 8px; }}
.card {{ border: 1px solid #ccc; padding: 4px; width: 392px; font-size: 11px; }}
.card.rejected {{ border-color: #c00; background: #fee; }}
.card.disagree {{ outline: 3px solid #f90; }}
.card img {{ width: 384px; image-rendering: pixelated; }}
code {{ font-size: 11px; }}
</style></head><body>
<h1>RoboView contact sheet ({n} candidates)</h1>
<p>Decisions file format (CSV): <code>instance_id,verdict,reviewer,note</code> with verdict
<code>accept</code> or <code>reject</code>; pass it to the next build with <code>--decisions=FILE</code>.</p>
<label>split <select id="split"><option value="">all</option>{split_options}</select></label>
<label>status <select id="status"><option value="">all</option><option>passed</option>
<option>rejected</option><option>disagree</option></select></label> <span id="count"></span>
<div class="grid">
{cards}
</div>
<script>
function apply() {{
  const s = document.getElementById('split').value, st = document.getElementById('status').value;
  let n = 0;
  for (const c of document.querySelectorAll('.card')) {{
    const show = (!s || c.dataset.split === s) && (!st || c.dataset.status.split(' ').includes(st));
    c.style.display = show ? '' : 'none'; n += show;
  }}
  document.getElementById('count').textContent = n + ' shown';
}}
document.getElementById('split').onchange = apply;
document.getElementById('status').onchange = apply;
apply();
</script></body></html>
"""


def _card(record: dict, accepted: bool, rejected_by: str) -> str:
    fair = record["fairness"]
    numbers = "<br>".join(
        f"{c['camera']}: obj {c['object_visible']:.2f} ({c['object_pixels']} px, "
        f"{'in' if c['object_in_frame'] else 'OUT of'} frame), box {c['box_visible']:.2f}, "
        f"ΔE table {c['delta_e_table']:.1f}, ΔE nominal {c['delta_e_nominal']:.1f}"
        for c in fair["cameras"]
    )
    status = "passed" if accepted else "rejected"
    reason = (
        ""
        if accepted
        else f"<br><b>rejected by {html.escape(rejected_by)}</b>: {html.escape(fair['reject_reason'])}"
    )
    vlm = fair.get("vlm_answer") or ""
    if vlm:
        disagree = vlm in ("yes", "no") and (vlm == "yes") != fair["passed"]
        status += " disagree" if disagree else ""
        flag = " <b>DISAGREES with the gate</b>" if disagree else ""
        reason += (
            f"<br>VLM screen: <b>{html.escape(vlm)}</b>{flag} — {html.escape(fair.get('vlm_analysis') or '')}"
        )
    return (
        f'<div class="card {status}" data-split="{record["split"]}" data-status="{status}">'
        f'<img loading="lazy" src="previews/{record["instance_id"]}.png" alt="preview">'
        f"<br><code>{record['instance_id']}</code> {html.escape(record['split'])}: "
        f"{html.escape(record['factor'])} = <b>{html.escape(record['value'])}</b>"
        f"<br>{html.escape(record.get('task', DEFAULT_TASK))}: {html.escape(context_text(record))}"
        f"<br>{numbers}{reason}</div>"
    )


def context_text(record: dict) -> str:
    """The instance's context values (its task's context factors), e.g. 'center, cube, “put …”'."""
    names = context_factors(record.get("task") or DEFAULT_TASK)
    return ", ".join(f"“{record[n]}”" if n.endswith("instruction") else str(record[n]) for n in names)


def write_contact_sheet(out: Path, records: list[dict], accepted: list[bool], rejected_by: list[str]) -> Path:
    sheet = out / "contact_sheet"
    previews = sheet / "previews"
    previews.mkdir(parents=True, exist_ok=True)
    for record in records:
        (previews / f"{record['instance_id']}.png").write_bytes(record["preview"]["bytes"])
    splits = sorted({r["split"] for r in records})
    page = PAGE.format(
        n=len(records),
        split_options="".join(f"<option>{s}</option>" for s in splits),
        cards="\n".join(_card(r, a, w) for r, a, w in zip(records, accepted, rejected_by)),
    )
    (sheet / "index.html").write_text(page)
    return sheet / "index.html"
