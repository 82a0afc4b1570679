"""Is policy B better than policy A, or less biased? An adaptive paired comparison, decided in as few rounds as the
difference allows (docs/adaptive.md, "Comparing two policies in rounds").

    roboview-compare --results=outputs/eval/act_ref,outputs/eval/act_campose [--max_repeats=10 --alpha=0.05]

Both results folders must hold the same benchmark's (instance, repeat) pairs. The comparison looks after each round
(repeat) both completed, spends the type-I error over the `max_repeats` planned looks, and prints per split and
overall: `A better` / `B better` (success rate), `A less biased` / `B less biased` (cv_excess), `not separated`
(every planned look passed) or `undecided` with the rounds still needed. Run it between rounds:

    for r in 1 2 3 4 5 6 7 8 9 10; do
      roboview-evaluate ... --policy.path=A --eval.n_repeats=$r --output_dir=outputs/eval/A
      roboview-evaluate ... --policy.path=B --eval.n_repeats=$r --output_dir=outputs/eval/B
      roboview-compare --results=outputs/eval/A,outputs/eval/B --max_repeats=10 --stop_exit_code=true && break
    done

Each evaluate resumes its folder and runs only the new round. `--stop_exit_code=true` makes the command exit 0
once the overall SR verdict is reached (decided or not separated) and 3 while it is undecided.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from roboview.eval.reporting.report import load_results
from roboview.eval.running.results import counted
from roboview.eval.statistics.metrics import EpisodesError, MetricsConfig
from roboview.eval.statistics.sequential_compare import CompareDesign, compare_in_rounds
from roboview.pipelines._cli import cli_main, result_entries

UNDECIDED_EXIT = 3


@dataclass
class CompareConfig:
    # The two results folders (or episodes.parquet files), comma-separated: A,B (NAME=PATH names a policy).
    results: str = ""
    # Type-I error of a verdict, spent over every planned look.
    alpha: float = 0.05
    # The planned looks: one after each round, up to this many rounds (repeats).
    max_repeats: int = 10
    # Shape of the error spending: α·(k/K)^ρ spent by look k.
    rho: float = 1.0
    # Folder for compare.json (empty: print only).
    output_dir: str = ""
    # Exit 3 while the overall SR verdict is undecided (for a shell loop that runs rounds until it is).
    stop_exit_code: bool = False
    # The cv_excess test's statistics (--metrics.n_perm, --metrics.seed, …; docs/statistics.md).
    metrics: MetricsConfig = field(default_factory=lambda: MetricsConfig(n_perm=200, n_glm=1, max_perm=200))

    def __post_init__(self) -> None:
        if len(self.entries) != 2:
            raise ValueError(
                f"--results={self.results!r}: give exactly two results folders, A,B (got {len(self.entries)})"
            )
        self.design  # noqa: B018  (checks alpha, max_repeats and rho now)

    @property
    def entries(self) -> list[tuple[str | None, Path]]:
        return result_entries(self.results)

    @property
    def design(self) -> CompareDesign:
        return CompareDesign(self.alpha, self.max_repeats, self.rho)


def run(cfg: CompareConfig) -> dict:
    episodes, _ = load_results([p for _, p in cfg.entries], [n for n, _ in cfg.entries])
    episodes = counted(episodes)
    names = [str(p) for p in episodes["policy"].drop_duplicates()]
    if len(names) != 2:
        raise ValueError(
            f"--results hold {len(names)} policies ({', '.join(names)}); name the two apart with NAME=PATH"
        )
    result = compare_in_rounds(episodes, names[0], names[1], cfg.design, cfg.metrics)
    if cfg.output_dir:
        Path(cfg.output_dir).mkdir(parents=True, exist_ok=True)
        (Path(cfg.output_dir) / "compare.json").write_text(json.dumps(result, indent=2))
    return result


def _line(name: str, block: dict, key: str) -> str:
    r = block[key]
    if r is None:
        return ""
    delta = "" if r["delta"] is None else f" Δ {100 * r['delta']:+.2f}"
    if r["look"] is not None:
        return f"{key} {r['verdict']} at round {r['look']}{delta} (p {r['p']:.2g} ≤ {r['alpha_spent']:.3g} spent)"
    needs = r.get("needs")
    more = f", needs ≈{needs} more round(s)" if r["verdict"] == "undecided" and needs else ""
    return f"{key} {r['verdict']}{more}{delta}"


def _summary(cfg: CompareConfig, result: dict) -> None:
    a, b = result["policies"]
    print(f"[compare] A = {a}, B = {b}; α = {cfg.alpha:g} over {cfg.max_repeats} planned rounds")
    blocks = [("overall", result["overall"]), *result["splits"].items()]
    for name, block in blocks:
        parts = [_line(name, block, "sr"), _line(name, block, "cv_excess") if "cv_excess" in block else ""]
        print(
            f"  {name:<22} {block['rounds']} round(s) × {block['n_pairs_per_round']} pairs: "
            + "; ".join(filter(None, parts))
        )
    if cfg.stop_exit_code and result["overall"]["sr"]["verdict"] == "undecided":
        raise SystemExit(UNDECIDED_EXIT)


def main(args: list[str] | None = None) -> dict:
    return cli_main(CompareConfig, run, _summary, (ValueError, FileNotFoundError, EpisodesError), args)


if __name__ == "__main__":
    main()
