"""A third task added through the public extension points only: one module published as a package.

`lift` (grasp the object and hold it up) lives in a throwaway package outside this repository: its
context factors, its env (a `TaskEnv` with no target), its registry line and a preset. The package
declares itself under the `roboview.tasks` entry-point group, so every command — and every worker
process they spawn — registers it. The real command lines then build a benchmark of it, collect
expert demos of it and evaluate the privileged expert on it.
"""

import json
import os
import subprocess
import sys
import textwrap

import pyarrow.parquet as pq
import pytest

pytestmark = [
    pytest.mark.slow,
    pytest.mark.schedule_first,  # a build, collection and evaluation from the command line, ≈ 30 s: never last (tests/conftest.py)
]

LIFT_MODULE = textwrap.dedent('''
    """lift: grasp the small object and hold it at least 8 cm above the table."""

    import numpy as np

    from roboview.sim.motion import CARRY_Z
    from roboview.tasks import Task, TaskEnv, register_task
    from roboview.tasks.presets import register_preset
    from roboview.variation.factors import Factor, register_factor
    from roboview.variation.instances import SuiteConfig

    POSITIONS = {"center": (0.50, 0.12), "left": (0.45, 0.22)}
    register_factor(Factor(name="lift_position", kind="context", task="lift", values=tuple(POSITIONS),
                           baseline="center", doc="Named start xy of the object."))
    register_factor(Factor(name="lift_instruction", kind="context", task="lift",
                           values=("lift the small object",), baseline="lift the small object", doc="Words."))


    class LiftEnv(TaskEnv):
        task = "lift"
        instruction_factor = "lift_instruction"

        def place_context(self, values, rng):
            self.scene.place_object("cube", np.asarray(POSITIONS[values["lift_position"]]), 0.0)

        def is_success(self):
            pos, _ = self.object_pose()
            return bool(pos[2] > 0.08 and self.object_touches_robot())

        @staticmethod
        def plan(planner, obj_pos, obj_yaw, symmetry, reach, target_xy, arm_qpos, ee_pos=None):
            planner.plan(obj_pos, obj_yaw, symmetry, arm_qpos, box_xy=obj_pos[:2], release_z=CARRY_Z, ee_pos=ee_pos)


    register_task(Task(name="lift", gym_id="LiftDemo/Lift-v0", env="roboview_lift:LiftEnv",
                       success="the object is held 8 cm above the table", timeout_reason="object not lifted",
                       max_episode_steps=60))
    register_preset(SuiteConfig(preset="lift_demo", tasks=("lift",), splits=("color",), union_mode="dedupe",
                                value_subsets=(("color", ("red", "blue")),)))
''')


@pytest.fixture(scope="module")
def lift_package(tmp_path_factory) -> dict[str, str]:
    """The package on PYTHONPATH, with the dist-info that declares its entry point; the env to run commands in."""
    root = tmp_path_factory.mktemp("lift_pkg")
    (root / "roboview_lift.py").write_text(LIFT_MODULE)
    info = root / "roboview_lift-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: roboview-lift\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[roboview.tasks]\nlift = roboview_lift\n")
    return os.environ | {"PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}


def _run(env: dict[str, str], module: str, *args: str) -> subprocess.CompletedProcess:
    proc = subprocess.run(
        [sys.executable, "-m", module, *args], env=env, capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 0, f"{module} failed:\n{proc.stdout[-1500:]}\n{proc.stderr[-3000:]}"
    return proc


def test_a_third_task_is_one_module_built_collected_and_evaluated(lift_package, tmp_path):
    env = lift_package
    # Registered by the entry point alone: a preset of it, its gymnasium id and its context in every suite.
    probe = _run(env, "roboview.pipelines.plan", "--preset=lift_demo")
    assert "lift" in probe.stdout + probe.stderr

    bench = tmp_path / "bench"
    _run(
        env,
        "roboview.pipelines.build_benchmark",
        f"--output_dir={bench}",
        "--preset=lift_demo",
        "--num_workers=1",
        "--image_size=64",
    )
    manifest = json.loads((bench / "benchmark.json").read_text())
    rows = pq.read_table(next(bench.rglob("lift_color*.parquet"))).to_pylist()
    # 2 colors x 2 contexts (the baseline start, then "left"), every one the lift task's and past the gate.
    assert sorted((r["value"], r["task"]) for r in rows) == [("blue", "lift")] * 2 + [("red", "lift")] * 2
    assert {r["lift_position"] for r in rows} == {"center", "left"}
    assert "lift_color" in json.dumps(manifest)

    demos = tmp_path / "demos"
    _run(
        env,
        "roboview.pipelines.collect",
        "--dataset.repo_id=t/lift",
        f"--dataset.root={demos}",
        "--dataset.task=lift",
        "--dataset.num_episodes=1",
        "--dataset.image_size=64",
        "--dataset.cameras=[front]",
        "--num_workers=1",
    )
    tasks = pq.read_table(demos / "meta" / "tasks.parquet").to_pandas()
    assert "lift the small object" in set(tasks.index) | set(tasks.get("task", []))

    out = tmp_path / "eval"
    _run(
        env,
        "roboview.pipelines.evaluate",
        f"--benchmark.path={bench}",
        "--policy.type=expert",
        "--eval.n_repeats=1",
        "--eval.num_workers=1",
        f"--output_dir={out}",
    )
    episodes = pq.read_table(out / "episodes.parquet").to_pandas()
    # The privileged expert lifts the object in every episode, well before the 60-step limit.
    assert (
        len(episodes) == 4 and set(episodes["split"]) == {"lift_color"} and set(episodes["task"]) == {"lift"}
    )
    assert episodes["success"].all() and episodes["steps"].max() < 60


def test_a_task_without_context_factors_is_refused():
    from roboview.tasks import Task, register_task

    with pytest.raises(ValueError, match="'hover' has no context factors: register them first"):
        register_task(Task(name="hover", gym_id="X/Hover-v0", env="x:Y", success="-", timeout_reason="-"))
