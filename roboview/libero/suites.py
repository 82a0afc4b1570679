"""LIBERO's four evaluation suites as RoboView sees them: tasks, init states, step budgets, input validation.

The suites are LIBERO's own (`libero.libero.benchmark`, task order 0, as LeRobot and openpi use them); nothing is
re-typed here. The per-suite step budgets are read from the installed consumers' source, so RoboView always scores
with the budget the consumer it imitates would use:

- LeRobot 0.6.1: `TASK_SUITE_MAX_STEPS` in `lerobot/envs/libero.py` (spatial 280, object 280, goal 300, 10 520).
- openpi (`examples/libero/main.py`, not packaged): spatial 220, the others as LeRobot. vla-eval ships the same table as
  `MAX_STEP_MAPPING` in `vla_eval/benchmarks/libero/benchmark.py`, which is where it is read from.

The tables are parsed with `ast` (no import: importing either module pulls in torch, robosuite and LIBERO's envs).
"""

from __future__ import annotations

import ast
import importlib.util
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np

from roboview.libero.bootstrap import ensure_libero

SUITES = ("libero_spatial", "libero_object", "libero_goal", "libero_10")
CONSUMERS = ("lerobot", "openpi")
_STEP_TABLES = {
    "lerobot": ("lerobot.envs.libero", "TASK_SUITE_MAX_STEPS"),
    "openpi": ("vla_eval.benchmarks.libero.benchmark", "MAX_STEP_MAPPING"),
}


@dataclass(frozen=True)
class LiberoTask:
    """One task of a suite: what a policy is told and where LIBERO keeps its problem and init states."""

    suite: str
    task_id: int
    name: str
    language: str
    bddl_file: Path
    init_states_file: Path
    n_init_states: int

    def max_steps(self, consumer: str = "lerobot") -> int:
        """The episode step budget `consumer` ("lerobot" or "openpi") gives this task's suite."""
        return max_steps(self.suite, consumer)


def check_suite(suite: str) -> str:
    """`suite` if it is one of SUITES, else a one-line ValueError naming it and the allowed set."""
    if suite not in SUITES:
        raise ValueError(f"unknown LIBERO suite {suite!r}; allowed: {', '.join(SUITES)}")
    return suite


@cache
def _module_source(module: str) -> Path:
    spec = importlib.util.find_spec(module.rpartition(".")[0])
    if spec is None or not spec.submodule_search_locations:
        raise ImportError(f"{module} is not installed; it holds the LIBERO step budgets RoboView reads")
    return Path(next(iter(spec.submodule_search_locations))) / (module.rpartition(".")[2] + ".py")


@cache
def step_table(consumer: str) -> dict[str, int]:
    """The `{suite: max_steps}` literal `consumer` ships (see the module docstring for where)."""
    if consumer not in _STEP_TABLES:
        raise ValueError(f"unknown consumer {consumer!r}; allowed: {', '.join(CONSUMERS)}")
    module, name = _STEP_TABLES[consumer]
    tree = ast.parse(_module_source(module).read_text())
    for node in tree.body:
        targets = node.targets if isinstance(node, ast.Assign) else [getattr(node, "target", None)]
        if any(isinstance(t, ast.Name) and t.id == name for t in targets) and node.value is not None:
            return {str(k): int(v) for k, v in ast.literal_eval(node.value).items()}
    raise LookupError(f"{name} not found in {_module_source(module)}")


def max_steps(suite: str, consumer: str = "lerobot") -> int:
    """Episode step budget of `suite` under `consumer`'s convention (LeRobot: 280/280/300/520; openpi: 220 spatial)."""
    return step_table(consumer)[check_suite(suite)]


@cache
def _benchmark(suite: str):
    ensure_libero()
    from libero.libero import benchmark

    return benchmark.get_benchmark_dict()[check_suite(suite)](task_order_index=0)


@cache
def tasks(suite: str) -> tuple[LiberoTask, ...]:
    """Every task of `suite`, in LIBERO's order (task_id = index)."""
    bench = _benchmark(suite)
    libero_pkg = ensure_libero()
    bddl_root = Path(libero_pkg.get_libero_path("bddl_files"))
    init_root = Path(libero_pkg.get_libero_path("init_states"))
    out = []
    for task_id in range(bench.n_tasks):
        task = bench.get_task(task_id)
        init_file = init_root / task.problem_folder / task.init_states_file
        out.append(
            LiberoTask(
                suite=suite,
                task_id=task_id,
                name=task.name,
                language=task.language,
                bddl_file=bddl_root / task.problem_folder / task.bddl_file,
                init_states_file=init_file,
                n_init_states=len(load_init_states(init_file)),
            )
        )
    return tuple(out)


def get_task(suite: str, task_id: int) -> LiberoTask:
    """Task `task_id` of `suite`; a one-line ValueError names a bad suite or an out-of-range id."""
    all_tasks = tasks(check_suite(suite))
    if not (isinstance(task_id, (int, np.integer)) and 0 <= task_id < len(all_tasks)):
        raise ValueError(f"task_id {task_id!r} out of range for {suite}; allowed: 0..{len(all_tasks) - 1}")
    return all_tasks[int(task_id)]


@cache
def load_init_states(path: Path) -> np.ndarray:
    """A task's init states (n, state_dim) exactly as LeRobot loads them (`torch.load(..., weights_only=False)`)."""
    import torch

    states = torch.load(path, weights_only=False)  # nosec B614: LIBERO's own numpy pickles, from the package
    states = np.asarray(states)
    states.setflags(write=False)
    return states


def init_state(suite: str, task_id: int, init_state_id: int) -> np.ndarray:
    """The flattened MuJoCo state `init_state_id` of a task; one-line ValueError when out of range."""
    task = get_task(suite, task_id)
    if not (isinstance(init_state_id, (int, np.integer)) and 0 <= init_state_id < task.n_init_states):
        raise ValueError(
            f"init_state_id {init_state_id!r} out of range for {suite} task {task_id}; "
            f"allowed: 0..{task.n_init_states - 1}"
        )
    return load_init_states(task.init_states_file)[int(init_state_id)]
