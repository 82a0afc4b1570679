"""lerobot_async: a checkpoint served by LeRobot's own policy server gives the in-process type's episodes and actions.

The server is lerobot's real `lerobot.async_inference.policy_server`, started here as a subprocess on a free
loopback port; the client is `roboview.policies.lerobot_async`.
"""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from roboview.pipelines.evaluate import BenchmarkConfig, EvalConfig, EvaluateConfig, run
from roboview.policies.base import AgentView, Episode, PolicyConfig
from roboview.policies.errors import PolicyUnavailable
from roboview.policies.types import policy_config
from tests.helpers.evaluation import rows
from tests.helpers.servers import LeRobotServer, free_port

pytestmark = [
    pytest.mark.slow,
    pytest.mark.schedule_first,  # a trained checkpoint and LeRobot's server, ≈ 25 s: never last (tests/conftest.py)
]

ROW = ["instance_id", "repeat", "episode_seed", "success", "steps", "failure_reason"]


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    srv = LeRobotServer(tmp_path_factory.mktemp("lerobot_server"))
    yield srv
    srv.stop()


def evaluate(bench: Path, out: Path, policy: PolicyConfig):
    cfg = EvaluateConfig(
        BenchmarkConfig(str(bench), "color"),
        policy,
        EvalConfig(n_repeats=1, limit=2, num_workers=1, max_steps=6, image_size=0),
        str(out),
    )
    return run(cfg)


def test_served_checkpoint_runs_the_in_process_episodes(tiny_benchmark, tiny_checkpoint, server, tmp_path):
    in_process = policy_config("lerobot", path=str(tiny_checkpoint), device="cpu")
    local = evaluate(tiny_benchmark, tmp_path / "local", in_process)
    served_cfg = policy_config("lerobot_async", server=server.address, path=str(tiny_checkpoint))
    served = evaluate(tiny_benchmark, tmp_path / "served", served_cfg)
    assert local.episodes == served.episodes == 2
    pd.testing.assert_frame_equal(rows(tmp_path / "local")[ROW], rows(tmp_path / "served")[ROW])
    assert rows(tmp_path / "served")["policy"].tolist() == ["lerobot:act"] * 2
    # Where the policy ran goes into provenance; the server's address is no option a resume must match.
    entry = json.loads((tmp_path / "served" / "provenance.json").read_text())[-1]
    assert entry["policy_server"] == {
        "protocol": "lerobot_async",
        "servers": [server.address],
        "policy_type": "act",
        "pretrained_name_or_path": str(tiny_checkpoint.absolute()),
        "device": "cpu",
        "actions_per_chunk": 10,
    }
    run_info = json.loads((tmp_path / "served" / "run.json").read_text())
    assert run_info["policy"] == "lerobot_async" and run_info["policy_path"] == str(tiny_checkpoint)
    assert "server" not in run_info["policy_options"] and run_info["image_size"] == 64


def test_served_actions_equal_in_process_actions(tiny_benchmark, tiny_checkpoint, server):
    """Rows of a 2-step checkpoint all fail at max_steps, so compare what the model answers, step by step."""
    from roboview.benchmark.format import load_benchmark
    from roboview.policies.lerobot_policy import LeRobotPolicy
    from roboview.tasks import make_env

    config = policy_config("lerobot_async", server=server.address, path=str(tiny_checkpoint))
    items = load_benchmark(tiny_benchmark, ["color"]).splits["color"][:2]
    env = make_env(cameras=config.observed_cameras(), image_size=config.input_image_size())
    served, local = config.build(AgentView.of(env)), LeRobotPolicy(str(tiny_checkpoint), "cpu")
    episodes = []
    try:
        for seed, item in enumerate(items):
            obs, _ = env.reset(seed=seed, options={"instance": item.instance})
            episodes.append((obs, Episode.of(env, seed)))
            served.reset(episodes[-1][1])
            local.reset(episodes[-1][1])
            for _ in range(12):  # crosses the first 10-action chunk
                want = local.select_action(obs)
                np.testing.assert_allclose(served.select_action(obs), want, rtol=0, atol=1e-5)
                obs, *_ = env.step(want)
        assert served.round_trips == local.reads == 4  # one observation sent per chunk, not per step
        # Two envs in lockstep share one connection: each slot gets its own episode's chunk.
        batched = config.build_batched(AgentView.of(env), 2)
        for slot, (_, episode) in enumerate(episodes):
            batched.reset(episode, slot)
        got = batched.select_actions({slot: obs for slot, (obs, _) in enumerate(episodes)})
        for slot, (obs, episode) in enumerate(episodes):
            local.reset(episode)
            np.testing.assert_allclose(got[slot], local.select_action(obs), rtol=0, atol=1e-5)
        batched.close()
    finally:
        served.close()
        env.close()


def test_a_server_that_is_down_fails_before_any_rollout(tiny_benchmark, tiny_checkpoint, tmp_path, capsys):
    from roboview.pipelines.evaluate import main

    address = f"127.0.0.1:{free_port()}"
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exit_:
        main(
            [
                f"--benchmark.path={tiny_benchmark}",
                "--policy.type=lerobot_async",
                f"--policy.server={address}",
                f"--policy.path={tiny_checkpoint}",
                f"--output_dir={out}",
            ]
        )
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and f"policy server at {address} does not answer" in err, err
    assert not out.exists()
    # A checkpoint readable here acts in its own control: another one stops the run naming the flag, before the
    # server is even reached, and nothing is written.
    with pytest.raises(SystemExit) as exit_:
        main([f"--benchmark.path={tiny_benchmark}", "--policy.type=lerobot_async", f"--policy.server={address}",
              f"--policy.path={tiny_checkpoint}", "--policy.control=ee_delta", f"--output_dir={out}"])  # fmt: skip
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and "acts in 'joint'" in err and "pass --policy.control=joint" in err, err
    assert "Traceback" not in err and not out.exists()
    # A checkpoint not readable here needs its facts as flags, named in the error.
    with pytest.raises(
        ValueError, match=r"not a folder on this machine.*--policy\.cameras=.*--policy\.image_size="
    ):
        policy_config("lerobot_async", server=address, path="org/act_model")


def test_a_server_gone_mid_run_stops_the_run_naming_it(tiny_checkpoint, server):
    """Last in this file: it stops the module's server."""
    config = policy_config(
        "lerobot_async",
        server=server.address,
        path=str(tiny_checkpoint),
        reconnects=1,
        reconnect_backoff_s=0.1,
    )
    policy = config.build(None)
    obs = {
        "observation.state": np.zeros(8, np.float32),
        **{f"observation.images.{cam}": np.zeros((64, 64, 3), np.uint8) for cam in ("left_top", "wrist")},
    }
    episode = Episode("pick_place", "put the red cube in the box", 0, {}, 64)
    try:
        policy.reset(episode)
        assert policy.select_action(obs).shape == (8,)
        server.stop()
        policy.reset(episode)  # the next chunk is asked for at once
        with pytest.raises(
            PolicyUnavailable, match=rf"{server.address} is unreachable.*rerun the same command"
        ):
            policy.select_action(obs)
    finally:
        policy.close()
        server.stop()
