"""Adaptive against fixed-n evaluation on simulated splits with a known bias: episodes to a decision.

    python -m benchmarks.adaptive --output=outputs/bench/adaptive.json [--sims=1000]
    python -m benchmarks.adaptive --results=outputs/eval/act_ref_adaptive --output=outputs/bench/adaptive_real.json

For each design (values × contexts at SR 0.7, the paper's camera_euler / camera_pose shapes and a small
one) and true bias τ ∈ {0, 0.3, 0.6} (logit SD), `roboview.eval.statistics.adaptive.simulate` runs the group-sequential
design (α = 0.05, futility against τ = 0.6 at power 0.8, at most `max_repeats` rounds) on real binomial
tables with the real statistic and boundaries. The fixed-n reference is the number of repeats (interpolated between
whole repeats) at which the fixed design reaches the adaptive design's simulated power at τ = 0.6; its power is
simulated too (`roboview.eval.statistics.adaptive.fixed_power`: the same statistic, its critical value from
simulated null splits), so neither design is helped by the χ² reference. `saving` = 1 − adaptive episodes / fixed.

With `--results=DIR` (a folder written by `roboview.pipelines.evaluate --eval.adaptive=true`) it reads that run instead:
per split, the episodes the adaptive run spent and why it stopped, against the fixed-n design that reaches the
run's power at its τ with the split's shape and observed success rate (`fixed_power`, simulated).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from roboview.eval.running.results import PARQUET
from roboview.eval.statistics.adaptive import Design, fixed_power, read_record, simulate
from roboview.pipelines._cli import cli_main

DESIGNS = ((9, 4, 12), (9, 11, 5), (21, 11, 6))  # values, contexts, max_repeats


@dataclass
class AdaptiveBenchConfig:
    # JSON file to write.
    output: str = "outputs/bench/adaptive.json"
    # Simulated splits per design and τ.
    sims: int = 1000
    # A results folder of an adaptive evaluation: compare that run with fixed-n instead of simulating.
    results: str = ""
    # Shapes simulated, as VALUESxCONTEXTSxMAX_REPEATS (e.g. 21x40x5: LIBERO's camera_pose over its 40 tasks, init
    # states 0–4); empty: the paper's shapes and a small one.
    designs: list[str] = field(default_factory=list)
    # True success rate of every simulated context.
    sr: float = 0.7

    def __post_init__(self) -> None:
        if self.sims < 10:
            raise ValueError(f"--sims={self.sims} must be ≥ 10")
        for shape in self.designs:
            parts = shape.split("x")
            if len(parts) != 3 or not all(p.isdigit() and int(p) > 0 for p in parts):
                raise ValueError(
                    f"--designs entry {shape!r} invalid; allowed: VALUESxCONTEXTSxMAX_REPEATS, e.g. 21x40x5"
                )
        if self.results and read_record(Path(self.results)) is None:
            raise ValueError(
                f"--results={self.results} holds no adaptive.json: run roboview.pipelines.evaluate with "
                "--eval.adaptive=true into it first"
            )


def real_run(results: Path) -> dict:
    """Per split of an adaptive run: episodes spent and the stop, against fixed-n at the design's power and τ."""
    record = read_record(results)
    design = record["design"]
    episodes = pd.read_parquet(results / PARQUET)
    splits = {}
    for split, stop in record["splits"].items():
        rows = episodes[episodes["split"] == split]
        n_values, n_contexts, sr = (
            rows["value"].nunique(),
            rows["context_id"].nunique(),
            float(rows["success"].mean()),
        )
        rate = min(max(sr, 0.02), 0.98)
        fixed = next(
            (
                n
                for n in range(1, 41)
                if fixed_power(n_values, n_contexts, rate, design["tau"], n, design["alpha"], paths=2000)
                >= design["power"]
            ),
            40,
        )
        fixed_episodes = fixed * n_values * n_contexts
        splits[split] = {
            **stop,
            "values": n_values,
            "contexts": n_contexts,
            "sr": round(sr, 4),
            "fixed_repeats_equal_power": fixed,
            "fixed_episodes": fixed_episodes,
            "saving": round(1 - stop["episodes"] / fixed_episodes, 3),
        }
        print(
            f"[adaptive] {split} ({n_values}×{n_contexts}, SR {sr:.2f}): stopped {stop['stopped']} after "
            f"{stop['rounds']} round(s), {stop['episodes']} episodes vs fixed {fixed_episodes} ({fixed} repeats)",
            flush=True,
        )
    total = sum(s["episodes"] for s in splits.values()), sum(s["fixed_episodes"] for s in splits.values())
    return {
        "results": str(results),
        "design": design,
        "splits": splits,
        "episodes": total[0],
        "fixed_episodes": total[1],
        "saving": round(1 - total[0] / total[1], 3),
    }


def fixed_reference(
    n_values: int, n_contexts: int, power: float, max_repeats: int, sr: float = 0.7
) -> tuple[list[float], float]:
    """Simulated power of the fixed design at 1 … max_repeats + 4 repeats against τ = 0.6 (`fixed_power`: the same
    statistic, critical value from simulated null splits), and the repeats that reach `power`, interpolated
    between whole repeats (rounding up would flatter the adaptive design)."""
    curve = [fixed_power(n_values, n_contexts, sr, 0.6, n, 0.05) for n in range(1, max_repeats + 5)]
    if power > curve[-1]:
        return curve, float(len(curve))
    return curve, float(np.interp(power, np.maximum.accumulate(curve), np.arange(1, len(curve) + 1)))


def run(cfg: AdaptiveBenchConfig) -> dict:
    if cfg.results:
        out = real_run(Path(cfg.results))
        Path(cfg.output).parent.mkdir(parents=True, exist_ok=True)
        Path(cfg.output).write_text(json.dumps(out, indent=2))
        return out
    results = []
    designs = [tuple(map(int, shape.split("x"))) for shape in cfg.designs] or DESIGNS
    for n_values, n_contexts, max_repeats in designs:
        design = Design(alpha=0.05, tau=0.6, power=0.8, max_repeats=max_repeats)
        start = time.perf_counter()
        rows = {
            tau: simulate(n_values, n_contexts, cfg.sr, tau, design, cfg.sims, seed=7)
            for tau in (0.0, 0.3, 0.6)
        }
        power = rows[0.6]["rejection_rate"]
        curve, fixed = fixed_reference(n_values, n_contexts, power, max_repeats, cfg.sr)
        fixed_episodes = fixed * n_values * n_contexts
        results.append(
            {
                "values": n_values,
                "contexts": n_contexts,
                "max_repeats": max_repeats,
                "adaptive": {str(t): r for t, r in rows.items()},
                "fixed_power_by_repeats": [round(p, 4) for p in curve],
                "fixed_repeats_equal_power": round(fixed, 3),
                "fixed_episodes": round(fixed_episodes, 1),
                "saving": {
                    str(t): round(1 - r["mean_episodes"] / fixed_episodes, 3) for t, r in rows.items()
                },
                "seconds": round(time.perf_counter() - start, 1),
            }
        )
        print(
            f"[adaptive] {n_values}×{n_contexts}: type-I {rows[0.0]['rejection_rate']:.3f}, power(0.6) {power:.3f}; "
            f"episodes τ=0/0.3/0.6: "
            + "/".join(f"{rows[t]['mean_episodes']:.0f}" for t in (0.0, 0.3, 0.6))
            + f" vs fixed {fixed_episodes:.0f} ({fixed:.2f} repeats); saving "
            + "/".join(f"{results[-1]['saving'][str(t)]:.0%}" for t in (0.0, 0.3, 0.6)),
            flush=True,
        )
    out = {"sims": cfg.sims, "alpha": 0.05, "tau_design": 0.6, "sr": cfg.sr, "designs": results}
    Path(cfg.output).parent.mkdir(parents=True, exist_ok=True)
    Path(cfg.output).write_text(json.dumps(out, indent=2))
    return out


def main(args: list[str] | None = None) -> dict:
    return cli_main(AdaptiveBenchConfig, run, args=args)


if __name__ == "__main__":
    main()
