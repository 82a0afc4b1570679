"""A frozen RoboView benchmark as a vla-eval benchmark: `vla-eval run -c configs/vla_eval/roboview_tiny.yaml`.

A vla-eval task is one (instance, repeat) of the chosen splits, in the order `roboview.pipelines.evaluate` runs them
(each split's selected instances × `n_repeats`); its `name` is the instance id (vla-eval's per-task rates are
per-instance rates) and its `suite` the split (vla-eval's `tasks: [color]` filter keeps one split). An episode
resets the instance with RoboView's common-random-number seed of its (context, repeat), so it is the episode
`roboview.pipelines.evaluate` runs for that pair; run each task once (`episodes_per_task: 1`).

Observations follow vla-eval's conventions: `images` (camera → H×W×3 uint8), `task_description` (the
instance's instruction) and `state`: the 7 joint positions + gripper closure (`STATE_JOINT`) under `joint`
control, the pinch point's position, axis-angle and gripper (`STATE_EEF_POS_AA_GRIP`) under `ee_delta` /
`ee_abs`. Actions: `{"actions": vector}` in the layout of the env's control (`ACTION_SPECS`).

An episode's result holds `success`, `steps` (env steps taken), `failure_reason` (RoboView's words; empty
for a success), the instance id, split, repeat and episode seed, the isolation certificate and the
conformance verdict; the first episode a process runs also carries the full conformance record.
`python -m roboview.integrations.vla_eval.convert` turns vla-eval's export into a RoboView results folder.
"""

from __future__ import annotations

import logging
import os
import sys
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from vla_eval.benchmarks.base import StepBenchmark, StepResult
from vla_eval.specs import IMAGE_RGB, LANGUAGE, DimSpec
from vla_eval.types import Action, EpisodeResult, Observation, Task

from roboview.policies.serving.vla_eval_specs import ACTION_SPECS, STATE_SPECS

log = logging.getLogger(__name__)

# The fields of an episode's result that vla-eval aggregates (as mean_success, mean_steps).
METRIC_KEYS = {"success": "mean", "steps": "mean"}


def _names(value: str | list[str] | tuple[str, ...]) -> list[str]:
    """A comma-separated string or a YAML list, as a list of names."""
    items = value.split(",") if isinstance(value, str) else list(value)
    return [str(x).strip() for x in items if str(x).strip()]


def _cameras(cameras: str | list[str]) -> tuple[str, ...]:
    """params.cameras as camera names; ValueError for an unknown one or none."""
    from roboview.sim.cameras import ALL_CAMERAS

    names = tuple(_names(cameras))
    unknown = [c for c in names if c not in ALL_CAMERAS]
    if unknown or not names:
        raise ValueError(
            f"params.cameras={cameras!r}: unknown camera(s) {unknown or list(names)}; "
            f"allowed: {', '.join(ALL_CAMERAS)}"
        )
    return names


def _check_sizes(image_size: int, n_repeats: int, max_steps: int, contexts: int, limit: int) -> None:
    """params.image_size a side the env renders, the counts positive, the selections ≥ 0."""
    from roboview.sim.cameras import check_image_size

    check_image_size(image_size, "params.image_size")
    for name, value in (("n_repeats", n_repeats), ("max_steps", max_steps)):
        if value <= 0:
            raise ValueError(f"params.{name}={value} must be a positive count")
    for name, value in (("contexts", contexts), ("limit", limit)):
        if value < 0:
            raise ValueError(f"params.{name}={value} must be ≥ 0 (0 = all)")


def _chosen_splits(benchmark_path: str, splits: str | list[str]) -> list[str]:
    """The splits params.splits names in the benchmark folder (`all`: every split of it); ValueError for a missing
    folder or an unknown split."""
    from roboview.benchmark.format import available_splits

    if not benchmark_path or not Path(benchmark_path).is_dir():
        raise ValueError(
            f"params.benchmark_path={benchmark_path!r}: no such folder (a benchmark folder written by "
            "roboview-build-benchmark)"
        )
    names = _names(splits)
    available = available_splits(benchmark_path)
    chosen = available if names == ["all"] else names
    unknown = [s for s in chosen if s not in available]
    if unknown or not chosen:
        raise ValueError(
            f"params.splits={splits!r}: unknown split(s) {unknown or chosen}; the benchmark at "
            f"{benchmark_path} has: {', '.join(available)} (or `all`)"
        )
    return chosen


def _stop_cli(exc: ValueError) -> None:
    """Under `vla-eval run`, a bad param ends the run with one line and exit status 2 (vla-eval would print the
    traceback of its orchestrator); called from a library, the ValueError propagates."""
    if Path(sys.argv[0]).name == "vla-eval":
        print(f"error: {exc}", file=sys.stderr, flush=True)
        raise SystemExit(2) from None


class RoboViewBenchmark(StepBenchmark):
    """The (instance, repeat) episodes of a RoboView benchmark folder's splits.

    Args:
        benchmark_path: the benchmark folder (roboview.pipelines.build_benchmark's output).
        splits: splits to run, comma-separated or a list; `all` for every split of the folder.
        n_repeats: episodes per instance (repeats 0 … n_repeats-1, each its own task).
        contexts: only the first N task contexts of each split, every value of each; 0: all.
        limit: only the first N instances of each split (after `contexts`); 0: all.
        cameras: cameras observed, comma-separated or a list (front, left_top, right_top, wrist).
        image_size: square image side in pixels.
        max_steps: env steps before an episode ends as a failure (also vla-eval's default step limit).
        control: the action space: joint, ee_delta or ee_abs.
        send_images: include `images` in observations (false: a state-only policy, and no camera renders).
        send_state: include `state` in observations.
        allow_drift: run even when this machine renders or simulates the benchmark `different`ly from the
            machine that built it (the conformance check made when vla-eval asks for the tasks).
    """

    render_backends: ClassVar[frozenset[str]] = frozenset({"gpu"})

    @classmethod
    def configure_render(cls, mode: str) -> dict[str, str]:
        """EGL, as every RoboView command renders (a GPU's, or Mesa's where there is none)."""
        if mode != "gpu":
            raise NotImplementedError(f"{cls.__name__} renders with EGL (render: gpu), not {mode!r}")
        applied = {}
        for key in ("MUJOCO_GL", "PYOPENGL_PLATFORM"):
            if key not in os.environ:
                os.environ[key] = applied[key] = "egl"
        return applied

    def __init__(
        self,
        benchmark_path: str = "",
        splits: str | list[str] = "all",
        n_repeats: int = 1,
        contexts: int = 0,
        limit: int = 0,
        cameras: str | list[str] = "left_top,wrist",
        image_size: int = 224,
        max_steps: int = 120,
        control: str = "joint",
        send_images: bool = True,
        send_state: bool = True,
        allow_drift: bool = False,
    ) -> None:
        super().__init__()
        from roboview.benchmark.format import load_benchmark, select_items

        try:
            if control not in ACTION_SPECS:
                raise ValueError(f"params.control={control!r} unknown; allowed: {', '.join(ACTION_SPECS)}")
            self.cameras = _cameras(cameras)
            _check_sizes(image_size, n_repeats, max_steps, contexts, limit)
            chosen = _chosen_splits(benchmark_path, splits)
        except ValueError as exc:
            _stop_cli(exc)
            raise
        bench = load_benchmark(benchmark_path, chosen)
        self.benchmark_path = str(Path(benchmark_path).resolve())
        self.version = bench.version
        self.bench = bench
        self.n_repeats = n_repeats
        self.image_size, self.max_steps, self.control = image_size, max_steps, control
        self.send_images, self.send_state = send_images, send_state
        self.items = {split: select_items(bench.splits[split], contexts, limit) for split in chosen}
        self.allow_drift = allow_drift
        self.conformance: dict = {}
        self._conformance_reported = False
        self._envs: dict[str, Any] = {}
        self._env: Any = None
        self._error, self._isolation = "", ""
        self._info: dict = {}
        self._success = False

    # -- tasks ---------------------------------------------------------------------------------
    def get_tasks(self) -> list[Task]:
        """Every (instance, repeat), after roboview.pipelines.evaluate's start-of-run conformance check: `different`
        raises (unless params.allow_drift) before vla-eval runs any episode."""
        from roboview.benchmark import conformance
        from roboview.variation.instances import episode_seed

        if not self.conformance:
            self.conformance = conformance.gate(self.bench, self.allow_drift, "params.allow_drift").record()

        tasks = [
            {
                "name": item.record["instance_id"],
                "suite": split,
                "instance_id": item.record["instance_id"],
                "split": split,
                "context_id": item.record["context_id"],
                "repeat": repeat,
                "episode_seed": episode_seed(item.record["context_id"], repeat),
                "episode_unit": item.repetition.unit(item.instance, repeat),
                "value": item.record["value"],
                "benchmark_version": self.version,
                "item": item,
            }
            for split, items in self.items.items()
            for item in items
            for repeat in range(self.n_repeats)
        ]
        log.info(
            "RoboView benchmark %s: %d episodes (%s × %d repeats), conformance %s",
            self.version,
            len(tasks),
            ", ".join(f"{split} {len(items)}" for split, items in self.items.items()),
            self.n_repeats,
            self.conformance["verdict"],
        )
        return tasks

    def _env_for(self, task: str) -> Any:
        """One env per RoboView task (pick_place, push, …), made on first use and kept."""
        if task not in self._envs:
            from roboview.tasks import make_env

            self._envs[task] = make_env(
                task,
                cameras=self.cameras,
                image_size=self.image_size,
                max_steps=self.max_steps,
                lazy=True,
                control=self.control,
            )
        return self._envs[task]

    # -- episode -------------------------------------------------------------------------------
    def reset(self, task: Task) -> Any:
        from roboview.eval.running import isolation

        if task.get("episode_idx", 0):
            raise ValueError(
                f"episode {task['episode_idx']} of task {task['name']}: a RoboView task is one (instance, "
                "repeat) run once; set episodes_per_task: 1 and params.n_repeats for more repeats"
            )
        item = task["item"]
        self._env = self._env_for(item.instance.task)
        episode = item.episode(task["repeat"])
        obs, self._info = self._env.reset(seed=task["episode_seed"], options={"instance": episode})
        self._isolation = isolation.record(self._env, task["episode_seed"])
        self._error, self._success = "", False
        return obs

    @property
    def isolation(self) -> str:
        """The isolation certificate of the episode the last `reset` started ("" before any)."""
        return self._isolation

    def step(self, action: Action) -> StepResult:
        env = self._env
        raw = np.asarray(action.get("actions", action.get("action")), dtype=np.float32)
        if raw.shape != env.action_space.shape or not np.all(np.isfinite(raw)):
            # As roboview.pipelines.evaluate: the policy's failure, not the harness's.
            self._error = (
                f"policy error: action of shape {raw.shape} with values {raw.ravel()[:8]} "
                f"(the env takes {env.action_space.shape[0]} finite values)"
            )
            return StepResult(obs=None, reward=0.0, done=True, info={})
        obs, reward, self._success, truncated, self._info = env.step(raw)
        # The env truncates at max_steps and when the simulation turns unstable (its info says so).
        done = self._success or truncated
        return StepResult(obs=obs, reward=reward, done=done, info=self._info)

    def make_obs(self, raw_obs: Any, task: Task) -> Observation:
        from roboview.tasks.env import IMAGE_KEY, STATE_KEY

        obs: dict[str, Any] = {"task_description": self._env.instruction}
        if self.send_images:
            obs["images"] = {c: np.asarray(raw_obs[IMAGE_KEY.format(c)]) for c in self.cameras}
        if self.send_state:
            obs["state"] = raw_obs[STATE_KEY] if self.control == "joint" else self._env.ee_state()
        return obs

    def get_step_result(self, step_result: StepResult) -> EpisodeResult:
        from roboview.tasks import load_task

        env, task = self._env, self._task
        if self._success:
            reason = ""
        elif self._error or self._info.get("failure_reason"):
            reason = self._error or self._info["failure_reason"]
        elif env.steps >= env.max_steps:
            reason = load_task(env.task).timeout_failure(env.max_steps)
        else:
            reason = f"stopped by vla-eval's max_steps after {env.steps} of {env.max_steps} steps"
        result = {
            "success": bool(self._success),
            "steps": int(env.steps),
            "failure_reason": reason,
            "instance_id": task["instance_id"],
            "split": task["split"],
            "repeat": task["repeat"],
            "episode_seed": task["episode_seed"],
            "isolation": self._isolation,
            "conformance": self.conformance["verdict"],
        }
        if not self._conformance_reported:  # once per process: what provenance records
            result["conformance_record"] = self.conformance
            self._conformance_reported = True
        return result

    # -- declarations --------------------------------------------------------------------------
    def get_metric_keys(self) -> dict[str, str]:
        return dict(METRIC_KEYS)

    def get_metadata(self) -> dict[str, Any]:
        return {
            "max_steps": self.max_steps,
            "max_episodes_per_task": 1,
            "benchmark_version": self.version,
            "control": self.control,
        }

    def get_action_spec(self) -> dict[str, DimSpec]:
        return dict(ACTION_SPECS[self.control])

    def get_observation_spec(self) -> dict[str, DimSpec]:
        spec: dict[str, DimSpec] = {camera: IMAGE_RGB for camera in self.cameras if self.send_images}
        spec["language"] = LANGUAGE
        if self.send_state:
            spec["state"] = STATE_SPECS[self.control]
        return spec

    def render(self) -> np.ndarray | None:
        return None if self._env is None else self._env.render()

    def cleanup(self) -> None:
        for env in self._envs.values():
            env.close()
        self._envs.clear()
        self._env = None
