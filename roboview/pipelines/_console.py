"""Console scripts (`pyproject.toml` [project.scripts]), one per verb, as LeRobot ships `lerobot-train` and
`lerobot-eval`: `roboview-<verb>` runs `python -m roboview.pipelines.<verb>` (underscores become dashes:
`roboview-build-benchmark`) with the same flags.

The wrappers drop the verb's return value: a console script exits with `sys.exit(main())`, and a returned
object would become exit status 1.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

VERBS = (
    "audit",
    "build_benchmark",
    "collect",
    "coverage",
    "evaluate",
    "export_dataset",
    "leaderboard",
    "merge",
    "plan",
    "probe_grounding",
    "publish",
    "report",
    "serve_policy",
    "serve_vlm",
    "train",
    "verify",
)


def script_name(verb: str) -> str:
    """The console script of a verb: `build_benchmark` → `roboview-build-benchmark`."""
    return "roboview-" + verb.replace("_", "-")


def _script(module: str) -> Callable[[], None]:
    verb = module.rpartition(".")[2]

    def run() -> None:
        importlib.import_module(module).main()

    run.__name__ = run.__qualname__ = verb
    run.__doc__ = f"`{script_name(verb)}`: `python -m {module}`."
    return run


audit = _script("roboview.pipelines.audit")
build_benchmark = _script("roboview.pipelines.build_benchmark")
collect = _script("roboview.pipelines.collect")
coverage = _script("roboview.pipelines.coverage")
evaluate = _script("roboview.pipelines.evaluate")
export_dataset = _script("roboview.pipelines.export_dataset")
leaderboard = _script("roboview.pipelines.leaderboard")
merge = _script("roboview.pipelines.merge")
plan = _script("roboview.pipelines.plan")
probe_grounding = _script("roboview.pipelines.probe_grounding")
publish = _script("roboview.pipelines.publish")
report = _script("roboview.pipelines.report")
serve_policy = _script("roboview.pipelines.serve_policy")
serve_vlm = _script("roboview.pipelines.serve_vlm")
train = _script("roboview.pipelines.train")
verify = _script("roboview.pipelines.verify")
