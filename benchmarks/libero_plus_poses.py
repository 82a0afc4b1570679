"""LIBERO-plus's camera poses on another numerical stack: its own `_setup_camera` arithmetic run by another Python
(LIBERO-plus pins numpy < 2; RoboView runs numpy 2 and a newer scipy), compared with RoboView's poses here.

    python -m benchmarks.libero_plus_poses --python=/path/to/venv/bin/python
        [--output=outputs/bench/libero_plus_poses.json]

Why: the tests prove RoboView's arithmetic equals LIBERO-plus's code on RoboView's stack, for all 1,599 variants. A
LIBERO-plus install computes the same poses with its own numpy and scipy; this measures whether they agree there.
The other Python needs only numpy and scipy: LIBERO-plus's pose helpers and each problem's `_setup_camera` are taken
from its installed source (the problem modules' import of robosuite is skipped), and run on the base poses LIBERO's
problem classes set. Writes a JSON (per problem: variants, differing positions and quaternions, the largest
difference) and prints a table.
"""

from __future__ import annotations

import json
import subprocess
from dataclasses import asdict, dataclass
from pathlib import Path

from roboview.core.cli import cli_main

# Runs in the other Python: reads {"sources": {problem: source}, "cases": [[problem, az, el, scale, rotz, roty]]}
# from stdin and prints each case's [pos, quat] as LIBERO-plus's `_setup_camera` sets agentview.
RUNNER = r"""
import ast, json, sys, types
import numpy as np
from scipy.spatial.transform import Rotation
request = json.load(sys.stdin)
classes = {}
for problem, source in request["sources"].items():
    tree = ast.parse(source)
    keep = [n for n in tree.body if isinstance(n, ast.FunctionDef)]
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef))
    method = next(n for n in cls.body if isinstance(n, ast.FunctionDef) and n.name == "_setup_camera")
    namespace = {"np": np, "Rotation": Rotation}
    exec(compile(ast.Module(keep + [method], []), problem, "exec"), namespace)
    classes[problem] = namespace["_setup_camera"]
class Recorder:
    def __init__(self):
        self.cameras = {}
    def set_camera(self, camera_name, pos, quat, camera_attribs=None):
        self.cameras[camera_name] = [list(map(float, pos)), list(map(float, quat))]
out = []
for problem, az, el, scale, rotz, roty in request["cases"]:
    this = types.SimpleNamespace(horizon_view=str(az), vertical_view=str(el), scale_factor=float(int(scale) / 100),
                                 end_point_rot=str(rotz), end_point_vertical=str(roty))
    recorder = Recorder()
    classes[problem](this, recorder)
    out.append(recorder.cameras["agentview"])
json.dump({"numpy": np.__version__, "scipy": __import__("scipy").__version__, "poses": out}, sys.stdout)
"""


@dataclass
class PosesConfig:
    # The other Python (numpy and scipy installed), e.g. a venv with LIBERO-plus's numpy < 2.
    python: str = ""
    # JSON file the comparison is written to.
    output: str = "outputs/bench/libero_plus_poses.json"

    def __post_init__(self) -> None:
        if not self.python:
            raise ValueError("--python is required: the interpreter to run LIBERO-plus's arithmetic with")
        if not Path(self.python).is_file():
            raise ValueError(f"--python={self.python!r} is not a file")


def run(cfg: PosesConfig) -> dict:
    import numpy as np
    import scipy

    from roboview.libero import plus
    from roboview.libero.bootstrap import ensure_libero
    from roboview.libero.suites import get_task

    ensure_libero()
    import libero.libero.envs.problems  # noqa: F401
    from libero.libero.envs.bddl_base_domain import TASK_MAPPING
    from libero.libero.envs.bddl_utils import get_problem_info

    problems = [
        get_problem_info(str(get_task(v.suite, v.task_id).bddl_file))["problem_name"] for v in plus.variants()
    ]
    folder = plus.package_root() / "liberoplus" / "envs" / "problems"
    sources = {p: (folder / f"{p}.py").read_text() for p in set(problems)}
    cases = [[p, *v.view.params] for p, v in zip(problems, plus.variants())]
    answer = subprocess.run(
        [cfg.python, "-c", RUNNER],
        input=json.dumps({"sources": sources, "cases": cases}),
        capture_output=True,
        text=True,
        check=True,
    )
    theirs = json.loads(answer.stdout)
    per_problem: dict[str, dict] = {}
    for problem, variant, (pos, quat) in zip(problems, plus.variants(), theirs["poses"]):
        ours = plus.liberoplus_pose(*plus.base_pose(TASK_MAPPING[problem]), variant.view)
        row = per_problem.setdefault(
            problem, {"variants": 0, "pos_differ": 0, "quat_differ": 0, "max_abs": 0.0}
        )
        row["variants"] += 1
        row["pos_differ"] += ours[0] != pos
        row["quat_differ"] += ours[1] != quat
        row["max_abs"] = max(
            row["max_abs"], float(np.max(np.abs(np.r_[ours[0], ours[1]] - np.r_[pos, quat])))
        )
    result = {
        "config": asdict(cfg),
        "here": {"numpy": np.__version__, "scipy": scipy.__version__},
        "there": {"numpy": theirs["numpy"], "scipy": theirs["scipy"]},
        "per_problem": per_problem,
        "identical": all(r["pos_differ"] == r["quat_differ"] == 0 for r in per_problem.values()),
    }
    out = Path(cfg.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2))
    return result


def _summary(cfg: PosesConfig, result: dict) -> None:
    here, there = result["here"], result["there"]
    print(
        f"RoboView: numpy {here['numpy']}, scipy {here['scipy']}; other: numpy {there['numpy']}, scipy {there['scipy']}"
    )
    print(f"{'problem':44} {'variants':>8} {'pos ≠':>6} {'quat ≠':>6} {'max |Δ|':>9}")
    for problem, r in result["per_problem"].items():
        print(
            f"{problem:44} {r['variants']:>8} {r['pos_differ']:>6} {r['quat_differ']:>6} {r['max_abs']:>9.1e}"
        )
    print(f"{'identical' if result['identical'] else 'NOT identical'}; wrote {cfg.output}")


def main(args: list[str] | None = None) -> dict:
    return cli_main(PosesConfig, run, _summary, args=args)


if __name__ == "__main__":
    main()
