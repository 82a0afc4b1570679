"""report.md's sections on how the results were obtained rather than what they say: the episodes infrastructure
ended, sample sizes and calibration with the control arm, adaptive sampling, the isolation certificate, the
simulation stack each run was checked on, and the provenance of each results file. Each function returns its
section's Markdown lines, empty when it has nothing to say.
"""

from __future__ import annotations

import json
from typing import Any

from roboview.eval.reporting.format import p_fmt, pct
from roboview.eval.reporting.tables import markdown_table
from roboview.eval.running import isolation


def diagnostics_section(layouts: dict[str, dict]) -> list[str]:
    """Per split: instances, episodes, contexts, how its p-values were calibrated; then the control arm's
    test-retest agreement."""
    rows = []
    for name, layout in layouts.items():
        for split, m in layout["splits"].items():
            rows.append(
                [
                    name,
                    split,
                    str(m["n_instances"]),
                    str(m["n_episodes"]),
                    str(m["n_contexts"]),
                    str(m["n_contexts_all_failed"]),
                    m["p_value_method"] or "—",
                    p_fmt(m["p_value_cv"], m.get("p_value_cv_at_floor"))
                    + (f" ({m['p_value_cv_draws']} draws)" if m.get("p_value_cv_draws") else ""),
                ]
            )
    control = [
        f"- {name}: baseline instance agrees across splits in {pct(c['agreement'])} % of {c['n_pairs']} "
        f"(context, repeat) pairs; baseline SR by split: "
        + ", ".join(f"{s} {pct(v)}" for s, v in c["sr_by_split"].items())
        for name, layout in layouts.items()
        if (c := layout.get("control"))
    ]
    return [
        "## Sample sizes, calibration and the control arm",
        "",
        *markdown_table(
            [
                "Policy",
                "Split",
                "Instances",
                "Episodes",
                "Contexts",
                "Contexts all failed",
                "p calibration",
                "p (CV permutation)",
            ],
            rows,
        ),
        "Control arm (test–retest): the all-baseline instance of each context runs, with the same seeds, in "
        "the color, camera_euler and dist_scale splits.",
        *control,
        "",
    ]


def adaptive_section(layouts: dict[str, dict]) -> list[str]:
    """Splits evaluated adaptively: rounds, episodes and why each stopped."""
    rows = [
        [
            name,
            split,
            str(a["rounds"]),
            str(a["episodes"]),
            a["stopped"],
            "—" if a["lrt"] is None else f"{a['lrt']:.2f}",
            "—" if a["efficacy_boundary"] is None else f"{a['efficacy_boundary']:.2f}",
            "—" if a["futility_boundary"] is None else f"{a['futility_boundary']:.2f}",
        ]
        for name, layout in layouts.items()
        for split, m in layout["splits"].items()
        if (a := m.get("adaptive"))
    ]
    if not rows:
        return []
    design = next(
        m["adaptive"]["design"]
        for layout in layouts.values()
        for m in layout["splits"].values()
        if m.get("adaptive")
    )
    return [
        "## Adaptive sampling",
        "",
        f"Repeats ran in rounds; from round {design['min_rounds']} on, after each round, a group-sequential LRT decided "
        f"(α = {design['alpha']} over every look, futility against a bias of logit SD τ = {design['tau']} at power "
        f"{design['power']}, at most {design['max_repeats']} rounds; docs/adaptive.md). The sampling was adaptive: "
        "the fixed-sample statistics in the tables above treat the episodes run as a fixed sample, and their "
        "p-values are approximate; the stop below is the sequential test's decision.",
        "",
        *markdown_table(
            ["Policy", "Split", "Rounds", "Episodes", "Stopped", "LRT", "efficacy bound", "futility bound"],
            rows,
        ),
        "",
    ]


def isolation_section(layouts: dict[str, dict]) -> list[str]:
    """Per split: how many (context, repeat) blocks were verified to differ only in the factor (eval/running/isolation.py)."""
    rows, violations = [], []
    for name, layout in layouts.items():
        for split, m in {**layout["splits"], **layout.get("interactions", {})}.items():
            cert = m.get("isolation")
            if cert is None:
                continue
            if not cert["recorded"]:
                rows.append([name, split, "—", str(cert["blocks"]), "not recorded", "—"])
                continue
            bad = cert["violations"]
            rows.append(
                [
                    name,
                    split,
                    isolation.label(cert),
                    str(cert["blocks"]),
                    f"{cert['verified']} / {cert['blocks']}",
                    "none" if not bad else f"{len(bad)} (left out of the tests)",
                ]
            )
            violations += [
                f"- {name}, {split}: context {v['context_id']} repeat {v['repeat']} — "
                f"{', '.join(v['components'])} differ across {', '.join(v['values'][:6])}"
                f"{' …' if len(v['values']) > 6 else ''}"
                for v in bad[:20]
            ]
    if not rows:
        return []
    return [
        "## Isolation certificate",
        "",
        "Every value of one (context, repeat) must share the instruction, the initial robot state and object pose, "
        "the episode seed, every other factor's value and the calibration of the cameras the factor does not move. "
        "*Changes* says what a split's values change: one factor (isolated), or more (a two-factor split, or an "
        "instruction that names the value), whose effects it cannot tell apart.",
        "",
        *markdown_table(["Policy", "Split", "Changes", "Blocks", "Verified identical", "Violations"], rows),
        *violations,
        "",
    ]


def infra_section(layouts: dict[str, dict]) -> list[str]:
    """Per split: the episodes infrastructure ended, left out of every number (`n_infra_errors`)."""
    lines = []
    for name, layout in layouts.items():
        listed = 0
        for split, m in {**layout["splits"], **layout.get("interactions", {})}.items():
            if m.get("n_infra_errors"):
                listed += m["n_infra_errors"]
                lines.append(
                    f"- {name}, {split}: {m['n_infra_errors']} episode(s) ended by infrastructure, not counted"
                )
        if layout.get("n_infra_errors", 0) > listed:
            lines.append(
                f"- {name}: {layout['n_infra_errors'] - listed} more episode(s) ended by infrastructure, not "
                "counted, in splits where no episode counts"
            )
    if not lines:
        return []
    return [
        "## Episodes ended by infrastructure",
        "",
        "Episodes ended by infrastructure, not by the policy (a policy server lost mid-episode, an endpoint still "
        "failing after its retries, a worker that died, a render failure; `status` infra_error, the reason in "
        "`failure_reason`) are left out of every rate and test. Rerunning the evaluation command into the same "
        "output folder runs them again.",
        "",
        *lines,
        "",
    ]


def copies_section(layouts: dict[str, dict]) -> list[str]:
    """Per split: the seed-only repeats of LIBERO episodes, copies of repeat 0 left out (`n_seed_only_copies`)."""
    lines = [
        f"- {name}, {split}: {m['n_seed_only_copies']} repeat(s) of an instance from its own init state, not counted"
        for name, layout in layouts.items()
        for split, m in {**layout["splits"], **layout.get("interactions", {})}.items()
        if m.get("n_seed_only_copies")
    ]
    if not lines:
        return []
    return [
        "## Repeats that were copies",
        "",
        "These results were recorded before repeats on LIBERO's scenes ran distinct init states: every repeat of an "
        "instance started from the instance's own init state, and the episode seed moves nothing but fixtures, so "
        "repeat r re-ran repeat 0's episode. Each instance counts once (its repeat 0); re-run the evaluation with "
        "this version for repeats that are distinct LIBERO episodes.",
        "",
        *lines,
        "",
    ]


def stack_section(sources: list[dict[str, Any]]) -> list[str]:
    """Per results file: the conformance verdict of each run with its measured drift and stack; then what differs
    between the stacks the files ran on (their numbers compare only as far as their stacks do)."""
    from roboview.sim import stack

    lines, seen = ["## Simulation stack and conformance", ""], []
    for source in sources:
        for entry in source.get("provenance") or []:
            conf = entry.get("conformance")
            if not conf:
                lines.append(f"- `{source['path']}` ({entry['started']}): no conformance check recorded")
                continue
            d = conf["drift"]
            lines.append(
                f"- `{source['path']}` ({entry['started']}): **{conf['verdict']}** on "
                f"{stack.summary(conf.get('stack'))}; {d['images_identical']}/{d['images']} reference images "
                f"and {d['physics_identical']}/{d['physics']} rollouts bit-identical, at most "
                f"{d['pixel_fraction_max']:.3%} of an image's pixels differ, joints within {d['joint_max']:.1e} rad"
            )
            if conf.get("stack_differences"):
                lines.append(
                    f"  - differs from the stack that built the benchmark: {'; '.join(conf['stack_differences'])}"
                )
            seen.append((source["path"], conf.get("stack"), conf["verdict"]))
    for path, other, verdict in seen[1:]:
        differences = stack.differences(seen[0][1], other)
        if differences or verdict != seen[0][2]:
            lines.append(
                f"- **The runs differ**: `{seen[0][0]}` ({seen[0][2]}) vs `{path}` ({verdict}): "
                f"{'; '.join(differences) or 'same stack'}"
            )
    return lines + [""] if len(lines) > 2 else []


def provenance_section(sources: list[dict[str, Any]]) -> list[str]:
    """What produced each results file: versions, checkpoint hash, command, machine, times."""
    lines = ["## Provenance", ""]
    for source in sources:
        for entry in source.get("provenance") or []:
            ckpt = entry.get("checkpoint") or {}
            packages = ", ".join(f"{k} {v}" for k, v in entry["packages"].items() if v)
            machine = entry["machine"]
            lines += [
                f"- `{source['path']}`: {entry['started']} → {entry.get('ended') or 'interrupted'}, "
                f"{entry.get('episodes_run', '?')} episodes; roboview commit {entry.get('roboview_commit') or '—'}",
                f"  - command: `{entry['command']}`",
                f"  - packages: {packages}",
                f"  - benchmark {entry['benchmark_version']}; checkpoint "
                f"{(ckpt.get('path', '') + ' sha256 ' + ckpt.get('sha256', '')[:16] + '…') if ckpt else '—'}",
                f"  - machine: {machine['cpu']} × {machine['cpu_count']}, GPU {machine.get('gpu') or 'none'}; "
                f"seeds: {entry['seed_rule']}",
            ]
            if entry.get("policy_server"):
                lines.append(
                    f"  - policy served elsewhere (its randomness is the server's, not the episode seeds'): "
                    f"{_served(entry['policy_server'])}"
                )
    return lines + [""] if len(lines) > 2 else []


def _served(server: dict) -> str:
    """One line for a served policy's provenance: protocol, where, and what the server said about itself."""
    where = server.get("urls") or server.get("servers") or server.get("server") or "?"
    where = ", ".join(where) if isinstance(where, list) else str(where)
    said = {
        url: meta.get("roboview", meta) if isinstance(meta, dict) else meta
        for url, meta in (server.get("metadata") or {}).items()
    }
    return f"{server.get('protocol', '?')} at {where}" + (
        f"; server metadata {json.dumps(said)}" if said else ""
    )
