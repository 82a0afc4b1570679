"""`python -m roboview.libero`: link LIBERO's assets for LIBERO's own code and print the LIBERO_CONFIG_PATH to export
(then LeRobot's `lerobot-eval --env.type=libero` runs offline here too)."""

from roboview.libero.bootstrap import main

main()
