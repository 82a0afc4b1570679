"""Publishing on the Hugging Face Hub: a built benchmark (with its contact sheet, a collected LeRobot dataset and
the EnvHub env, on request) and a verified result bundle. hub.py: the plan of an upload, the authenticated API;
benchmark.py: a benchmark's release; results.py: a result bundle, staged and uploaded."""
