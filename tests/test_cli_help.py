"""Every entry point answers --help (argparse formats field comments: a stray % once crashed one)."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
ENTRY_POINTS = ("collect", "build_benchmark", "publish", "evaluate", "report", "plan", "train", "coverage", "serve_vlm",
                "probe_grounding", "export_dataset", "serve_policy", "audit", "merge")


# The LeRobot side's own commands.
LEROBOT_SIDE = ("roboview_lerobot.convert", "roboview_lerobot.tiny_vla")


@pytest.mark.parametrize("module", [f"pipelines.{name}" for name in ENTRY_POINTS] + list(LEROBOT_SIDE))
def test_help_documents_the_flags(module):
    proc = subprocess.run([sys.executable, "-m", module, "--help"], capture_output=True, text=True,
                          timeout=120, cwd=ROOT, env=os.environ | {"PYTHONPATH": str(ROOT)})
    assert proc.returncode == 0, proc.stderr[-1500:]
    assert "usage:" in proc.stdout and "--" in proc.stdout and "Traceback" not in proc.stderr


def test_every_pipeline_module_is_covered():
    modules = {p.stem for p in (ROOT / "pipelines").glob("*.py") if not p.stem.startswith("_")}
    assert modules == set(ENTRY_POINTS)
