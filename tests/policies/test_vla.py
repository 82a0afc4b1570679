"""VLAs (SmolVLA and XVLA: tiny, random weights, nothing downloaded) trained by lerobot-train on RoboView demos,
then evaluated through `roboview.pipelines.evaluate --policy.type=lerobot` and through `lerobot-eval --env.type=roboview`:
the instruction reaches the tokenizer, the four cameras the image inputs, the 8-D state the (padded) state."""

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from roboview.pipelines.evaluate import BenchmarkConfig, EvalConfig, EvaluateConfig
from roboview.pipelines.evaluate import run as evaluate
from roboview.policies.types import policy_config
from roboview.policies.vlm.client import Endpoint
from roboview.policies.vlm.sgl import SGLConfig
from roboview.sim.cameras import ALL_CAMERAS
from tests.helpers import cli

pytestmark = pytest.mark.slow

BIN = Path(sys.executable).parent


@pytest.fixture(scope="module")
def demos(tmp_path_factory) -> Path:
    """Two expert demos with all four cameras at 64²."""
    from roboview.pipelines.collect import CollectConfig, DatasetConfig
    from roboview.pipelines.collect import run as collect

    root = tmp_path_factory.mktemp("vla_demos") / "ds"
    collect(
        CollectConfig(
            DatasetConfig(
                repo_id="t/vla", root=str(root), num_episodes=2, image_size=64, cameras=list(ALL_CAMERAS)
            ),
            num_workers=1,
        )
    )
    return root


def _train(demos: Path, out: Path, flags: list[str]) -> Path:
    cmd = [
        str(BIN / "lerobot-train"),
        "--dataset.repo_id=t/vla",
        f"--dataset.root={demos}",
        *flags,
        "--policy.device=cpu",
        "--batch_size=2",
        "--steps=2",
        "--save_freq=2",
        "--num_workers=0",
        "--wandb.enable=false",
        f"--output_dir={out}",
        "--job_name=tiny_vla",
    ]
    proc = cli.run("lerobot.scripts.lerobot_train", *cmd[1:])  # the lerobot-train console script's module
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out / "checkpoints" / "last" / "pretrained_model"


@pytest.fixture(scope="module")
def tiny_vlas(demos, tmp_path_factory):
    """kind -> (checkpoint, tokenizer folder): a tiny VLA of that type trained 2 steps by lerobot-train, once."""
    from roboview.integrations.lerobot.tiny_vla import (
        smolvla_train_flags,
        write_bart_tokenizer,
        write_smolvlm,
        xvla_train_flags,
    )

    built: dict[str, tuple[Path, Path]] = {}

    def get(kind: str) -> tuple[Path, Path]:
        if kind not in built:
            root = tmp_path_factory.mktemp(kind)
            if kind == "smolvla":
                tokenizer = write_smolvlm(root / "smolvlm")
                flags = smolvla_train_flags(tokenizer)
            else:
                tokenizer = write_bart_tokenizer(root / "tokenizer")
                flags = xvla_train_flags(tokenizer)
            built[kind] = _train(demos, root / "train", flags), tokenizer
        return built[kind]

    return get


@pytest.fixture(scope="module", params=["smolvla", "xvla"])
def vla(request, tiny_vlas) -> tuple[str, Path, Path]:
    return request.param, *tiny_vlas(request.param)


@pytest.fixture(scope="module")
def smolvla(tiny_vlas) -> tuple[Path, Path]:
    return tiny_vlas("smolvla")


def _observation(instruction: str):
    from roboview.tasks import make_env
    from roboview.variation.factors import baselines
    from roboview.variation.instances import TaskInstance

    instance = TaskInstance(
        "color", ("color",), baselines() | {"instruction": instruction, "color": "blue"}, "base"
    )
    env = make_env(cameras=ALL_CAMERAS, image_size=64)
    obs, _ = env.reset(seed=3, options={"instance": instance})
    obs = {k: np.asarray(obs[k]) for k in obs}
    env.close()
    return obs


def test_the_instruction_cameras_and_state_reach_the_vla(vla):
    from transformers import AutoTokenizer

    from roboview.policies.lerobot_policy import LeRobotPolicy

    kind, checkpoint, tokenizer_dir = vla
    policy = LeRobotPolicy(str(checkpoint), "cpu")
    assert policy.name == f"lerobot:{kind}" and policy.chunked
    tokenizer = AutoTokenizer.from_pretrained(tokenizer_dir)
    said = "pick up the small object and place it in the yellow box"
    obs = _observation(said)
    batch = policy._batch([obs], [said])
    # The instruction, word for word, is what the tokenizer gave the model (nothing unknown, nothing dropped).
    mask = batch["observation.language.attention_mask"][0].bool()
    ids = batch["observation.language.tokens"][0][mask].tolist()
    words = [t for t in tokenizer.convert_ids_to_tokens(ids) if t not in tokenizer.all_special_tokens]
    assert words == said.split() and tokenizer.unk_token_id not in ids
    other = policy._batch([obs], ["move the small object into the yellow box"])[
        "observation.language.tokens"
    ][0]
    assert not np.array_equal(other.numpy(), batch["observation.language.tokens"][0].numpy())
    # Every camera under the key the checkpoint expects.
    assert sorted(k for k in batch if k.startswith("observation.images.")) == sorted(
        f"observation.images.{c}" for c in ALL_CAMERAS
    )
    if kind == "smolvla":  # the 8-D state padded to SmolVLA's 32 with zeros
        state = policy.policy.prepare_state(batch)
        assert state.shape == (1, policy.policy.config.max_state_dim) == (1, 32)
        assert np.array_equal(state[0, :8].numpy(), batch["observation.state"][0].numpy())
        assert not state[0, 8:].any() and state[0, :8].abs().sum() > 0
    # A chunk of n_action_steps 8-D actions, unnormalized into the env's action space.
    chunk = policy.predict_chunks({0: obs})[0]
    assert len(chunk) == policy.n_action_steps == 10 and all(a.shape == (8,) for a in chunk)
    assert all(np.isfinite(a).all() for a in chunk)


def _evaluate(bench: Path, out: Path, checkpoint: Path, sgl: SGLConfig | None = None, **policy_fields):
    config = policy_config("lerobot", path=str(checkpoint), device="cpu", **policy_fields)
    return evaluate(
        EvaluateConfig(
            BenchmarkConfig(str(bench), "color"),
            config,
            EvalConfig(n_repeats=1, limit=2, num_workers=1, max_steps=6),
            str(out),
            sgl=sgl or SGLConfig(),
        )
    )


def test_a_vla_checkpoint_evaluates_in_roboview_and_in_lerobot_eval(vla, tiny_benchmark, tmp_path):
    from roboview.integrations.lerobot.convert import convert

    kind, checkpoint, _ = vla
    result = _evaluate(tiny_benchmark, tmp_path / "ours", checkpoint)
    ours = pd.read_parquet(tmp_path / "ours" / "episodes.parquet")
    assert result.episodes == 2 and (ours["policy"] == f"lerobot:{kind}").all()
    assert (ours["steps"] == 6).all() and not ours["success"].any()  # random weights: every episode runs out
    args = [
        str(BIN / "lerobot-eval"),
        "--env.type=roboview",
        f"--env.benchmark_path={tiny_benchmark}",
        "--env.task=color",
        "--env.limit=2",
        f"--env.cameras={','.join(ALL_CAMERAS)}",
        "--env.image_size=64",
        "--env.max_steps=6",
        f"--policy.path={checkpoint}",
        "--policy.device=cpu",
        "--eval.n_episodes=2",
        "--eval.batch_size=2",
        f"--output_dir={tmp_path / 'le'}",
    ]
    proc = cli.run("lerobot.scripts.lerobot_eval", *args[1:])  # the lerobot-eval console script's module
    if kind == "xvla":
        # lerobot-eval 0.6.1 gives every XVLA policy LIBERO's env processors, whatever the env
        # (lerobot/envs/factory.py:50-53); they reject RoboView's images. XVLA runs through roboview.pipelines.evaluate.
        assert proc.returncode != 0 and "outside [0, 255] range" in proc.stderr
        return
    assert proc.returncode == 0, proc.stderr[-3000:]
    info = json.loads((tmp_path / "le" / "eval_info.json").read_text())
    assert info["per_group"]["color"]["n_episodes"] == 2 and info["per_group"]["color"]["pc_success"] == 0.0
    assert len(info["per_group"]["color"]["video_paths"]) == 2  # lerobot-eval's own episode videos
    converted = pd.read_parquet(
        convert(
            tmp_path / "le" / "eval_info.json",
            str(tiny_benchmark),
            tmp_path / "conv",
            limit=2,
            max_steps=6,
            image_size=64,
        )
    )
    assert converted["instance_id"].tolist() == ours["instance_id"].tolist()


def test_the_semantic_grounding_layer_rewrites_what_smolvla_reads(smolvla, tiny_benchmark, tmp_path):
    from transformers import AutoTokenizer

    from roboview.benchmark.format import load_benchmark
    from roboview.policies.base import Episode
    from roboview.policies.factory import make_policy
    from roboview.policies.vlm.standin import MODEL_NAME, ClassicCVModel
    from roboview.tasks import make_env
    from tests.helpers.vlm_servers import ScriptedServer

    checkpoint, backbone = smolvla
    server = ScriptedServer(ClassicCVModel())
    try:
        sgl = SGLConfig(enable=True, endpoint=Endpoint(server.url, MODEL_NAME))
        _evaluate(tiny_benchmark, tmp_path / "sgl", checkpoint, sgl)
        rows = pd.read_parquet(tmp_path / "sgl" / "episodes.parquet")
        assert (rows["policy"] == "lerobot:smolvla+sgl").all() and rows["sgl_ambiguous"].all()
        # "the small object" names the object by its colour in the instruction the checkpoint was reset with.
        for color, said, refined in zip(rows["color"], rows["instruction"], rows["sgl_instruction"]):
            assert refined.split()[:4] == said.split()[:3] + [color], refined
        # ... and those words, not the original ones, are what the checkpoint's tokenizer turns into tokens.
        item = load_benchmark(tiny_benchmark, ["color"]).splits["color"][0]
        config = sgl.wrap(policy_config("lerobot", path=str(checkpoint), device="cpu"))
        env = make_env(cameras=ALL_CAMERAS, image_size=64)
        obs, _ = env.reset(seed=0, options={"instance": item.instance})
        policy = make_policy(config, env)
        policy.reset(Episode.of(env, 0))
        policy.select_action(obs)
        env.close()
    finally:
        server.close()
    refined = policy.episode_record()["sgl_instruction"]
    assert policy.inner.tasks[0] == refined != item.instance.get("instruction")
    tokens = policy.inner._batch([obs], policy.inner.tasks)["observation.language.tokens"][0].tolist()
    tokenizer = AutoTokenizer.from_pretrained(backbone)
    assert tokenizer.convert_tokens_to_ids(refined.split()[3]) in tokens  # the colour word the SGL put in
    assert tokenizer.unk_token_id not in tokens


def test_a_checkpoint_is_found_by_hub_id_in_the_hub_cache(smolvla, tiny_benchmark, tmp_path):
    import shutil
    import uuid

    from huggingface_hub import constants

    checkpoint, _ = smolvla
    # The test run's own hub cache (under its cache folder, tests/conftest.py), the one a command-line run reads;
    # a repo name of this test's alone.
    repo = f"org/tiny-smolvla-{uuid.uuid4().hex[:8]}"
    folder = Path(constants.HF_HUB_CACHE) / f"models--{repo.replace('/', '--')}"
    snapshot = folder / "snapshots" / ("ab" * 20)
    shutil.copytree(checkpoint, snapshot)
    (folder / "refs").mkdir()
    (folder / "refs" / "main").write_text("ab" * 20)
    assert constants.HF_HUB_OFFLINE
    common = [
        "roboview.pipelines.evaluate",
        f"--benchmark.path={tiny_benchmark}",
        "--policy.type=lerobot",
        "--policy.device=cpu",
        "--benchmark.splits=color",
        "--eval.limit=1",
        "--eval.n_repeats=1",
        "--eval.max_steps=3",
        "--eval.num_workers=1",
    ]
    try:
        proc = cli.run(*common, f"--policy.path={repo}", f"--output_dir={tmp_path / 'ev'}")
    finally:
        shutil.rmtree(folder)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert pd.read_parquet(tmp_path / "ev" / "episodes.parquet")["policy"].tolist() == ["lerobot:smolvla"]
    provenance = json.loads((tmp_path / "ev" / "provenance.json").read_text())[0]
    assert provenance["checkpoint"]["path"] == str(snapshot.resolve())
    # An id in no hub cache: refused before any work.
    proc = cli.run(*common, "--policy.path=org/not-downloaded", f"--output_dir={tmp_path / 'no'}")
    assert proc.returncode == 2 and "'org/not-downloaded' is no local folder" in proc.stderr
    assert "not in the hub cache" in proc.stderr and not (tmp_path / "no").exists()
