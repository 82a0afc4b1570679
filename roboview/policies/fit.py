"""Whether a policy fits the envs of the tasks it is about to run on, checked once before any episode: the control
it acts in must be one every env takes and the cameras it observes ones every env renders. A policy whose control
is still open (a 7-d LeRobot checkpoint whose training dataset is not here to name it) takes the one end-effector
control every env shares — LIBERO's scenes take only `ee_delta`, so a LIBERO checkpoint needs no flag."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from roboview.policies.base import PolicyConfig
from roboview.tasks import load_task
from roboview.variation.instances import TaskInstance


def fit_policy(policy: PolicyConfig, tasks: Sequence[str], instances: Iterable[TaskInstance] = ()) -> None:
    """Settle the policy's open control against `tasks`' envs, then check its control and cameras against each
    env; a one-line ValueError naming the task, the policy's value and what the env allows. The scripted expert must
    also script every one of `instances` (LIBERO's scripts two of its four suites)."""
    envs = {task: load_task(task).env_class() for task in tasks}
    if not envs:
        return
    if policy.type == "expert":
        unscripted = sorted(
            {load_task(i.task).world_of(i) for i in instances if not _expert(i.task).scripts(i)}
        )
        if unscripted:
            raise ValueError(
                f"the scripted expert does not script {len(unscripted)} of the chosen worlds "
                f"({', '.join(unscripted[:4])}{' …' if len(unscripted) > 4 else ''}); evaluate a benchmark of the "
                "ones it scripts (LIBERO: libero_object and libero_spatial, e.g. --preset=liberoplus_camera_object)"
            )
    shared = [
        c
        for c in next(iter(envs.values())).world.controls
        if all(c in e.world.controls for e in envs.values())
    ]
    policy.settle_control(tuple(shared))
    control = policy.env_control()
    for task, env in envs.items():
        if control not in env.world.controls:
            # A checkpoint acts in the control its action was trained in: another flag cannot fit it.
            settable = hasattr(policy, "control") and not policy.checkpoint
            hint = f" (pass --policy.control={env.world.controls[0]})" if settable else ""
            raise ValueError(
                f"the {task!r} task's env takes control {', '.join(env.world.controls)}; {describe(policy)} acts in "
                f"{control!r}{hint}"
            )
        if policy.privileged and env.world.privileged_cameras:
            continue  # a privileged policy is given the world's own cameras
        missing = [c for c in policy.observed_cameras() if c not in env.world.cameras]
        if missing:
            raise ValueError(
                f"{describe(policy)} observes camera(s) {', '.join(missing)}, which the {task!r} task's env does "
                f"not render; its cameras: {', '.join(env.world.cameras)}"
            )


def _expert(task: str):
    from roboview.tasks.base import resolve

    return resolve(load_task(task).expert)


def describe(policy: PolicyConfig) -> str:
    """`--policy.type=lerobot (DIR)`: the policy as the command line named it."""
    where = f" ({policy.checkpoint})" if policy.checkpoint else ""
    return f"--policy.type={policy.type}{where}"
