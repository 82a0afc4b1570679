"""LIBERO's scenes as a RoboView world: LeRobot-exact baselines, lazy rendering, in-place visual factors.

- `bootstrap.ensure_libero()`: makes `import libero` work offline with no prompt (config + registry assets).
  Call it before anything imports `libero.libero` (LeRobot's `lerobot.envs.libero` does at import).
- `suites`: the four suites (spatial, object, goal, 10), their tasks, init states and step budgets.
- `env.LiberoWorld`: one (suite, task, init state), built and reset exactly as LeRobot 0.6.1's `LiberoEnv`.
- `factors`: visual appliers (object color, agentview pose, lighting, table texture) re-applied after each reset.
- `task` (the `libero` world and task) and `plus_task` (LIBERO-plus's `liberoplus` task and presets): `roboview.tasks`
  entry points (pyproject.toml), imported when a registry is first read; `presets` (LIBERO's suite presets) and `view`
  (LIBERO-plus's `view_*` factors) register with `task`.

Nothing here imports LIBERO, robosuite or torch at import time; they load when a world or suite is first used.
"""

from roboview.libero.bootstrap import PIP_INSTALL, LiberoMissing, ensure_libero
from roboview.libero.env import LiberoWorld, lerobot_state, lerobot_view
from roboview.libero.suites import SUITES, LiberoTask, get_task, init_state, max_steps, tasks

__all__ = [
    "PIP_INSTALL",
    "SUITES",
    "LiberoMissing",
    "LiberoTask",
    "LiberoWorld",
    "ensure_libero",
    "get_task",
    "init_state",
    "lerobot_state",
    "lerobot_view",
    "max_steps",
    "tasks",
]
