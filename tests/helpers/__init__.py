"""What the tests share: the repository root, command-line runs forked from a preloaded process (cli.py), servers
started on 127.0.0.1 (servers.py), episode tables (episodes.py), headless Chromium (browser.py), the scripted VLM
servers (vlm_servers.py) and the test-only policy type (parting_policy.py). Built benchmarks, demos and checkpoints
are tests/conftest.py's session fixtures."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
