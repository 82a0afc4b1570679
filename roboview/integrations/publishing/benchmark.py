"""A built benchmark's release on the Hub: the folder uploaded to a dataset repo and tagged with its version; a
collected LeRobot dataset through lerobot's own push_to_hub, and RoboView as a LeRobot EnvHub env, on request."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from roboview.benchmark.format import MANIFEST
from roboview.integrations.publishing.hub import Plan, folder_files, hub_api

CONTACT_SHEET = "contact_sheet/*"


@dataclass(frozen=True)
class Release:
    """A benchmark folder and where it goes: its dataset repo (private or not), the contact sheet or not, a
    collected LeRobot dataset's folder and repo, and the EnvHub repo (None: none)."""

    path: Path
    repo_id: str
    private: bool = False
    include_contact_sheet: bool = False
    lerobot_root: str | None = None
    lerobot_repo_id: str | None = None
    env_repo_id: str | None = None

    @property
    def ignored(self) -> list[str]:
        """The benchmark folder's files left out of the upload."""
        return [] if self.include_contact_sheet else [CONTACT_SHEET]


def release_plan(release: Release) -> Plan:
    """Every file the release uploads, with its size, and the version the upload is tagged with."""
    version = json.loads((release.path / MANIFEST).read_text())["benchmark_version"]
    lerobot = folder_files(Path(release.lerobot_root), ["images/*"]) if release.lerobot_root else []
    env = env_hub_files(release.env_repo_id, release.repo_id, version) if release.env_repo_id else {}
    return Plan(release.repo_id, version, folder_files(release.path, release.ignored), lerobot, env)


def env_hub_files(env_repo_id: str, benchmark_repo_id: str, version: str) -> dict[str, str]:
    """The EnvHub repo: RoboView's env.py (make_env) and a README that points it at the benchmark repo."""
    import roboview.integrations.lerobot

    env_py = (Path(roboview.integrations.lerobot.__file__).parent / "hub" / "env.py").read_text()
    readme = (
        f"---\ntags: [lerobot, envhub, roboview, robot-learning, visual-bias]\n---\n"
        f"# RoboView-Bias ({version}) as a LeRobot EnvHub environment\n\n"
        f"Frozen, factor-isolated splits of the RoboView-Bias benchmark (`{benchmark_repo_id}`).\n"
        "Needs the `roboview` package installed beside lerobot.\n\n"
        "```python\nimport os\nfrom lerobot.envs.factory import make_env\n\n"
        f'os.environ["ROBOVIEW_BENCHMARK"] = "{benchmark_repo_id}"\n'
        'os.environ["ROBOVIEW_TASK"] = "color,camera_pose"\n'
        f'envs = make_env("{env_repo_id}", n_envs=4, trust_remote_code=True)\n```\n\n'
        "Settings: see the docstring of `env.py`.\n"
    )
    return {"env.py": env_py, "README.md": readme}


def upload_release(release: Release, plan: Plan) -> str:
    """Upload the planned release (PublishError before any change when the hub cannot be used); the commit."""
    api = hub_api()
    api.create_repo(release.repo_id, repo_type="dataset", private=release.private, exist_ok=True)
    commit = api.upload_folder(
        folder_path=str(release.path),
        repo_id=release.repo_id,
        repo_type="dataset",
        ignore_patterns=release.ignored or None,
        commit_message=f"RoboView benchmark {plan.version}",
    )
    api.create_tag(release.repo_id, tag=plan.version, repo_type="dataset", exist_ok=True)
    if release.env_repo_id:
        from huggingface_hub import CommitOperationAdd

        api.create_repo(release.env_repo_id, private=release.private, exist_ok=True)
        api.create_commit(
            release.env_repo_id,
            [CommitOperationAdd(path, text.encode()) for path, text in plan.env_files.items()],
            commit_message=f"RoboView EnvHub env for {release.repo_id} {plan.version}",
        )
    if release.lerobot_root:
        from lerobot.datasets.lerobot_dataset import LeRobotDataset

        LeRobotDataset(release.lerobot_repo_id, root=release.lerobot_root).push_to_hub(
            tags=["roboview", "franka-panda", "mujoco"], private=release.private
        )
    return str(commit)
