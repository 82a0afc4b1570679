"""How many repeats does each split need? Power of the GLM likelihood-ratio test, before any rollout.

    roboview-plan --preset=paper --tau=0.3 --sr=0.7
    roboview-plan --benchmark.path=outputs/benchmark --tau=0.5 --power=0.9

A policy "has a bias of logit SD τ" when the log-odds of success move by value with standard
deviation τ (τ = 0.3: a value at +1 SD succeeds at 76 % where one at −1 SD succeeds at 64 %, around
a 70 % policy). For each split the test of `value + context` against `context` has |V| − 1 degrees
of freedom and, at n repeats, non-centrality λ ≈ n · |C| · (|V| − 1) · τ² · p(1 − p); the power is
the non-central χ² tail beyond the χ² critical value (scipy.stats.ncx2). A factorial split is
planned per factor: its strata are (other value, context). Pass the result to roboview.pipelines.evaluate
with `--eval.split_repeats=split=N,...`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from roboview.eval.campaign.power import SplitPlan, plan_splits, split_layouts
from roboview.pipelines._cli import BenchmarkPath, cli_main


@dataclass
class PlanConfig:
    # Suite preset to plan for (paper, paper_dedupe, tiny), used when --benchmark.path is empty.
    preset: str = "paper"
    # A built benchmark folder to plan for instead of a preset (--benchmark.path).
    benchmark: BenchmarkPath = field(default_factory=BenchmarkPath)
    # Bias to detect: standard deviation of the value effects on the logit scale.
    tau: float = 0.3
    # Expected success rate of the policy (the test has most power near 0.5).
    sr: float = 0.7
    # Power wanted (probability of p < alpha when the bias is there).
    power: float = 0.8
    # Level of the test.
    alpha: float = 0.05

    def __post_init__(self) -> None:
        if not self.tau > 0:
            raise ValueError(f"--tau={self.tau} must be > 0 (a bias of size 0 cannot be detected)")
        for name in ("sr", "power", "alpha"):
            if not 0 < getattr(self, name) < 1:
                raise ValueError(f"--{name}={getattr(self, name)} must lie strictly between 0 and 1")


def run(cfg: PlanConfig) -> list[SplitPlan]:
    layouts = split_layouts(cfg.benchmark.path, cfg.preset)
    return plan_splits(layouts, cfg.tau, cfg.sr, cfg.power, cfg.alpha)


def _summary(cfg: PlanConfig, plans: list[SplitPlan]) -> None:
    print(
        f"Repeats per instance for {cfg.power:.0%} power to detect a logit-SD {cfg.tau:g} bias at "
        f"α = {cfg.alpha:g}, success rate ≈ {cfg.sr:.0%} (GLM likelihood-ratio test):"
    )
    print(f"{'split':<22}{'factor':<14}{'|V|':>5}{'strata':>8}{'repeats':>9}{'power at 5':>12}")
    for p in plans:
        need = ">1000" if p.repeats is None else str(p.repeats)
        print(f"{p.split:<22}{p.factor:<14}{p.n_values:>5}{p.n_strata:>8}{need:>9}{p.power_at_5:>12.2f}")
    single = ",".join(
        f"{p.split}={p.repeats}" for p in plans if p.repeats is not None and "_x_" not in p.split
    )
    print(f"\nFor roboview.pipelines.evaluate: --eval.split_repeats={single}" if single else "")


def main(args: list[str] | None = None) -> list[SplitPlan]:
    return cli_main(PlanConfig, run, _summary, (ValueError,), args)


if __name__ == "__main__":
    main()
