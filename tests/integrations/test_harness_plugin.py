"""A result-file format of another harness added from its own package (the `roboview.harnesses` entry-point
group), read by `roboview-audit --format=NAME` with no change to RoboView."""

import json
import os
import subprocess
import sys

import pytest

pytestmark = pytest.mark.slow

READER = """
import json
import pandas as pd
from roboview.eval.running.harnesses.base import HarnessTable

def read(path):
    rows = [json.loads(line) for line in open(path)]
    table = pd.DataFrame(rows)
    return HarnessTable(table, {"factor": "perturbation", "value": "level", "context": "task", "success": "ok"},
                        f"{len(rows)} episodes of my_harness")
"""


def test_a_harness_reader_from_another_package_is_audited(tmp_path):
    package = tmp_path / "pkg"
    package.mkdir()
    (package / "my_harness_reader.py").write_text(READER)
    info = package / "my_harness_reader-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: my-harness-reader\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[roboview.harnesses]\nmy_harness = my_harness_reader:read\n")
    # Level "hard" succeeds 1 time in 6 per task, "easy" 5 in 6: the audit must count exactly that.
    results = tmp_path / "episodes.jsonl"
    with results.open("w") as fh:
        for task in ("t0", "t1", "t2"):
            for level, wins in (("easy", 5), ("hard", 1)):
                for i in range(6):
                    row = {"perturbation": "camera", "level": level, "task": task, "ok": i < wins}
                    fh.write(json.dumps(row) + "\n")
    env = os.environ | {"PYTHONPATH": os.pathsep.join([str(package), os.environ.get("PYTHONPATH", "")])}
    out = tmp_path / "audit"
    proc = subprocess.run(
        [sys.executable, "-m", "roboview.pipelines.audit", "--format=my_harness", f"--results={results}",
         f"--output_dir={out}", "--metrics.n_perm=200", "--metrics.n_glm=30", "--metrics.max_perm=200"
        ],
        env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    split = json.loads((out / "metrics.json").read_text())["splits"]["camera"]
    assert split["n_episodes"] == 36 and split["per_value"]["easy"]["sr"] == 15 / 18
    assert split["per_value"]["hard"]["sr"] == 3 / 18
    unknown = subprocess.run(
        [sys.executable, "-m", "roboview.pipelines.audit", "--format=nope", f"--results={results}",
         f"--output_dir={out}"],
        env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert (
        unknown.returncode != 0
        and "known: vla_eval, inspect_robots, gauntlet, xevals, my_harness" in unknown.stderr
    )
