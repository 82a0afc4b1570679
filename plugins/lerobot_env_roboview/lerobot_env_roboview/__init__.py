"""LeRobot imports this module at start-up, found by its distribution name (`lerobot_env_*`): importing
roboview.integrations.lerobot registers the `roboview` EnvConfig, so `lerobot-eval --env.type=roboview` and
`lerobot-train --env.type=roboview` need no `--env.discover_packages_path`."""

import roboview.integrations.lerobot  # noqa: F401  (registers the EnvConfig and the gymnasium id on import)
