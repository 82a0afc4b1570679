"""Roll out a policy over the frozen benchmark instances and append one row per episode.

    roboview-evaluate --benchmark.path=outputs/benchmark --policy.type=vision \
        --eval.n_repeats=5 --eval.num_workers=2 --output_dir=outputs/eval/vision

Each (instance, repeat) runs once with seed SHA-256(f"{context_id}:{repeat}") — common random
numbers: every value of a context runs repeat r with the same seed; episodes stop early on
success. `--eval.protocol=paper` runs the paper's 5 repeats (10 on the factorial split). Rows go to OUT/episodes.parquet (journalled in OUT/episodes.jsonl as they
finish). Rerunning the same command resumes: finished pairs are skipped, none is duplicated. An episode
that infrastructure ended (a lost policy server, an endpoint outage, a dead worker, a render failure) is
recorded with status infra_error, counted in no rate, run again after the pass (`--eval.max_infra_retries`)
and by a rerun, its new row replacing the old.
"""

from __future__ import annotations

from roboview.eval.campaign.config import BenchmarkConfig, EvalConfig, EvaluateConfig
from roboview.eval.campaign.runner import EvaluateResult, Plan, plan, run
from roboview.eval.running.backends import ClusterLost
from roboview.eval.running.results import ResultsError
from roboview.pipelines._cli import cli_main
from roboview.policies.errors import PolicyUnavailable
from roboview.policies.types import load_policy_types

__all__ = ["BenchmarkConfig", "EvalConfig", "EvaluateConfig", "EvaluateResult", "Plan", "main", "plan", "run"]


def rate_text(result: EvaluateResult) -> str:
    """ "N new, SR x%, R episodes/h"; a rerun with nothing left to run says so instead of printing 0/h or nan."""
    sr = "SR —" if result.success_rate != result.success_rate else f"SR {result.success_rate:.1%}"
    if not result.new_episodes:
        return f"already complete, nothing new to run; {sr}"
    return f"{result.new_episodes} new, {sr}, {result.episodes_per_hour:.0f} episodes/h"


def summary(cfg: EvaluateConfig, result: EvaluateResult) -> None:
    """The line the command prints when it ends: episodes, where, the rate, infrastructure errors."""
    infra = (
        f"; {result.infra_errors} ended by infrastructure errors (status infra_error), counted in no rate: "
        "rerun the same command to re-run them"
        if result.infra_errors
        else ""
    )
    policy = cfg.policy.name or cfg.policy.type
    if cfg.policy.privileged:
        policy += " (privileged: reads the simulator state; a ceiling, not a policy's result)"
    print(
        f"[evaluate] {result.episodes} episodes of {policy} in {result.output_dir / 'episodes.parquet'} "
        f"({rate_text(result)}{infra})"
    )
    if cfg.eval.rerun:
        from roboview.eval.running.rerun_log import recordings

        files = recordings(cfg.eval.rerun)
        print(
            f"[evaluate] Rerun recording{'s' if len(files) > 1 else ''} of {cfg.eval.rerun}: "
            + (f"rerun {' '.join(map(str, files))}" if files else "none yet (no episode was recorded)")
        )


def main(args: list[str] | None = None) -> EvaluateResult:
    # Builtin and plugin policy types load first, so --policy.type can name any of them.
    from roboview.benchmark.conformance import ConformanceError

    return cli_main(
        EvaluateConfig,
        run,
        summary,
        (ValueError, ResultsError, ClusterLost, PolicyUnavailable, ConformanceError),
        args,
        before_parse=load_policy_types,
    )


if __name__ == "__main__":
    main()
