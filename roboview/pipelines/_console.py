"""Console scripts (`pyproject.toml` [project.scripts]), one per verb, as LeRobot ships `lerobot-train` and
`lerobot-eval`: `roboview-<verb>` runs `python -m roboview.pipelines.<verb>` (underscores become dashes:
`roboview-build-benchmark`) with the same flags.

The wrappers drop the verb's return value: a console script exits with `sys.exit(main())`, and a returned
object would become exit status 1.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

# The verb modules, one per console script (their names as strings: the import graph sees them).
MODULES = (
    "roboview.pipelines.audit",
    "roboview.pipelines.build_benchmark",
    "roboview.pipelines.collect",
    "roboview.pipelines.compare",
    "roboview.pipelines.coverage",
    "roboview.pipelines.evaluate",
    "roboview.pipelines.export_dataset",
    "roboview.pipelines.leaderboard",
    "roboview.pipelines.merge",
    "roboview.pipelines.pair",
    "roboview.pipelines.plan",
    "roboview.pipelines.probe_grounding",
    "roboview.pipelines.publish",
    "roboview.pipelines.report",
    "roboview.pipelines.serve_policy",
    "roboview.pipelines.serve_vlm",
    "roboview.pipelines.train",
    "roboview.pipelines.verify",
)
VERBS = tuple(module.rpartition(".")[2] for module in MODULES)


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


def __getattr__(name: str) -> Callable[[], None]:
    """`roboview.pipelines._console:<verb>`, the entry point of `roboview-<verb>` (PEP 562)."""
    if name in VERBS:
        return _script(MODULES[VERBS.index(name)])
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
