"""Meta-World's scenes as a RoboView world (docs/metaworld.md), in this wing only:

- `env.MetaWorldScene`: one task's env, built, seeded and observed exactly as LeRobot 0.6.1's `MetaworldEnv`.
- `factors`: the visual factors' appliers on Meta-World's compiled model (object color, corner2's pose, lighting,
  table texture), re-applied after every reset.
- `task`: the `metaworld` world and task (its contexts, env, expert and registry lines), a `roboview.tasks` entry
  point (pyproject.toml): the registries import it when first read.
- `presets`: its suite presets, registered with its task.
- `probe`: the fairness gate's probe.

Nothing here imports Meta-World at import time; it loads when a scene is first built (`make install-metaworld`).
"""
