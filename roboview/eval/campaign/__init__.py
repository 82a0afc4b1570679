"""An evaluation campaign, the top room of eval/: what a run is asked to do (config.py: `--benchmark.*`,
`--eval.*`, `--policy.*`), its plan checked against the loaded benchmark before any episode (plan.py), the run itself
(runner.py: the worker pool or Ray cluster, resume, infrastructure retries; rounds.py: adaptive rounds), and what
is made of campaigns: the repeats a wanted power needs (power.py), another tool's episodes audited (audit.py), a
leaderboard of verified and replayed bundles (board.py), the MOKA grounding-deviation probe (grounding_probe.py)."""
