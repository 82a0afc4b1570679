"""Meta-World's scenes as a RoboView world (docs/metaworld.md), in this wing only:

- `env.MetaWorldScene`: one task's env, built, seeded and observed exactly as LeRobot 0.6.1's `MetaworldEnv`.
- `factors`: the visual factors' appliers on Meta-World's compiled model (object color, corner2's pose, lighting,
  table texture), re-applied after every reset.
- `task`: the `metaworld` world and task (its contexts, env, expert and registry lines).
- `probe`: the fairness gate's probe.

Nothing here imports Meta-World at import time; it loads when a scene is first built (`make install-metaworld`).
"""

# The task registry first: a module of this wing imported on its own (`import roboview.metaworld.task`) then finds
# every task and preset registered, its own included, instead of a registry half built around it.
import roboview.tasks  # noqa: E402, F401
