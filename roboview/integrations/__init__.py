"""RoboView inside other harnesses: LeRobot's lerobot-eval / lerobot-train and vla-eval."""
