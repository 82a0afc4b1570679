"""Join the results folders of a sharded evaluation into one.

    roboview-evaluate ... --eval.shard=0/2 --output_dir=outputs/eval/act_shard0   # machine A
    roboview-evaluate ... --eval.shard=1/2 --output_dir=outputs/eval/act_shard1   # machine B
    roboview-merge --results=outputs/eval/act_shard0,outputs/eval/act_shard1 --output_dir=outputs/eval/act

The merged folder is an ordinary results folder (run.json, episodes.jsonl, episodes.parquet, provenance.json,
videos), so `roboview.pipelines.report` reads it as it reads an unsharded run. Refused before anything is written:
folders of different runs (benchmark version, policy, options, repeats, image size), shards of different
counts, a shard given twice, a missing shard (unless --partial=true) and any episode in two folders.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from roboview.eval.running.results import PARQUET, ResultsError, merge_folders
from roboview.pipelines._cli import cli_main


@dataclass
class MergeConfig:
    # Results folders of one sharded run (roboview.pipelines.evaluate --eval.shard=i/N), comma-separated.
    results: str = ""
    # Folder that receives the merged results (new, or a previous merge of the same shards).
    output_dir: str = "outputs/eval/merged"
    # Merge even when some shards of the run are missing (their episodes are simply absent).
    partial: bool = False

    def __post_init__(self) -> None:
        from roboview.eval.running.inputs import results_folder_problem

        missing = [str(f) for f in self.folders if not f.exists()]
        if missing:
            raise ValueError(
                f"--results names folder(s) that do not exist: {', '.join(missing)}; expected the "
                "results folders of one sharded run (roboview.pipelines.evaluate --eval.shard=i/N --output_dir)"
            )
        for folder in self.folders:
            problem = results_folder_problem(folder)
            if problem:
                raise ValueError(f"--results: {problem}")
        if len(self.folders) < 2:
            raise ValueError(
                f"--results={self.results!r} must name two results folders or more, comma-separated"
            )

    @property
    def folders(self) -> list[Path]:
        return [Path(x.strip()) for x in self.results.split(",") if x.strip()]


@dataclass(frozen=True)
class MergeResult:
    output_dir: Path
    per_folder: dict[str, int]

    @property
    def episodes(self) -> int:
        return sum(self.per_folder.values())


def run(cfg: MergeConfig) -> MergeResult:
    _, per_folder = merge_folders(cfg.folders, Path(cfg.output_dir), partial=cfg.partial)
    return MergeResult(Path(cfg.output_dir), per_folder)


def _summary(cfg: MergeConfig, result: MergeResult) -> None:
    print(
        f"[merge] {result.episodes} episodes from {len(result.per_folder)} shards in "
        f"{result.output_dir / PARQUET}"
    )


def main(args: list[str] | None = None) -> MergeResult:
    return cli_main(MergeConfig, run, _summary, (ResultsError,), args)


if __name__ == "__main__":
    main()
