"""openpi's websocket protocol, both ways, against real servers on 127.0.0.1.

RoboView's `openpi` client against openpi-server's own `WebsocketPolicyServer` serving a tiny ACT
checkpoint (rows equal to in-process evaluation; error frame, wrong chunk shape, a server killed mid-run
and resumed); openpi-client's own `WebsocketClientPolicy` against `roboview.pipelines.serve_policy` (actions equal
to in-process, requests of several connections batched into one forward pass).
"""

import json
import os
import re
import threading
import time
import urllib.request
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from roboview.pipelines.evaluate import BenchmarkConfig, EvalConfig, EvaluateConfig, run
from roboview.policies.base import Episode
from roboview.policies.errors import PolicyUnavailable
from roboview.policies.types import policy_config
from tests.helpers.evaluation import rows
from tests.helpers.servers import free_port, start_server, stop

pytestmark = pytest.mark.slow

COLS = ["instance_id", "repeat", "episode_seed", "success", "steps", "policy", "failure_reason"]


def evaluate(bench: Path, out: Path, policy, splits="color", limit=2, workers=2, max_steps=6) -> None:
    run(
        EvaluateConfig(
            BenchmarkConfig(str(bench), splits),
            policy,
            EvalConfig(n_repeats=1, limit=limit, num_workers=workers, max_steps=max_steps, image_size=0),
            str(out),
        )
    )


def client(port: int, **settings):
    return policy_config(
        "openpi", url=f"ws://127.0.0.1:{port}", cameras="left_top,wrist", image_size=64, **settings
    )


@pytest.fixture(scope="module")
def openpi_server(tiny_checkpoint):
    """openpi-server's WebsocketPolicyServer (one request at a time) around the tiny checkpoint."""
    port = free_port()
    proc = start_server(tiny_checkpoint, port, "--server=openpi")
    yield port
    stop(proc)


@pytest.fixture(scope="module")
def reference(tiny_benchmark, tiny_checkpoint, tmp_path_factory) -> Path:
    """The same episodes evaluated in-process (2 workers: one torch thread each, as the server's --threads=1)."""
    out = tmp_path_factory.mktemp("inproc")
    evaluate(
        tiny_benchmark, out, policy_config("lerobot", path=str(tiny_checkpoint)), splits="color,camera_pose"
    )
    return out


def test_openpi_server_rows_equal_in_process_and_metadata_is_recorded(
    tiny_benchmark, openpi_server, reference, tmp_path
):
    evaluate(tiny_benchmark, tmp_path / "served", client(openpi_server), splits="color,camera_pose")
    served, local = rows(tmp_path / "served"), rows(reference)
    assert len(served) == 4
    pd.testing.assert_frame_equal(
        served[COLS[:-2] + ["failure_reason"]], local[COLS[:-2] + ["failure_reason"]]
    )
    assert set(served["policy"]) == {"openpi:droid"}
    entry = json.loads((tmp_path / "served" / "provenance.json").read_text())[-1]
    meta = entry["policy_server"]["metadata"][f"ws://127.0.0.1:{openpi_server}"]["roboview"]
    assert entry["policy_server"]["protocol"] == "openpi"
    assert (
        meta["policy"] == "lerobot:act"
        and meta["image_size"] == 64
        and meta["cameras"] == ["left_top", "wrist"]
    )
    assert "url" not in json.loads((tmp_path / "served" / "run.json").read_text())["policy_options"]
    # The report says where the policy was served and what the server said.
    from roboview.eval.reporting.run_sections import provenance_section

    lines = provenance_section([{"path": "served", "provenance": [entry]}])
    line = next(x for x in lines if "served elsewhere" in x)
    assert f"openpi at ws://127.0.0.1:{openpi_server}" in line and '"policy": "lerobot:act"' in line


def test_client_actions_equal_the_checkpoint_in_process(tiny_benchmark, tiny_checkpoint, openpi_server):
    from roboview.benchmark.format import load_benchmark
    from roboview.policies.base import AgentView
    from roboview.policies.lerobot_policy import LeRobotPolicy
    from roboview.tasks import make_env

    item = load_benchmark(tiny_benchmark, ["color"]).splits["color"][1]
    env = make_env(cameras=("left_top", "wrist"), image_size=64)
    obs, _ = env.reset(seed=3, options={"instance": item.instance})
    episode = Episode.of(env, 3)
    remote = client(openpi_server, replan_steps=4).build(AgentView.of(env))
    local = LeRobotPolicy(str(tiny_checkpoint), "cpu")
    remote.reset(episode)
    local.reset(episode)
    for t in range(8):  # two requests: the client uses 4 actions (replan_steps) of each 10-action chunk
        if t % 4 == 0:
            chunk = local.predict_chunks({0: obs})[0]
        action = remote.select_action(obs)
        np.testing.assert_allclose(action, chunk[t % 4], rtol=0, atol=1e-5)
        obs, *_ = env.step(action)
    assert remote.requests == 2 and len(chunk) == 10
    remote.close()
    env.close()


def test_a_server_that_errors_or_answers_the_wrong_shape_stops_the_run_before_any_episode(
    tiny_benchmark, openpi_server, tmp_path
):
    """openpi's metadata declares nothing of what the model answers, so the first step of the first instance runs
    as a pre-flight: a server that raises on the request (it expects DROID keys and is sent LIBERO's) or answers
    7-D actions to an 8-D env stops the run there with the cause, and no episode is written."""
    with pytest.raises(ValueError) as err:
        evaluate(tiny_benchmark, tmp_path / "libero", client(openpi_server, obs_format="libero"), limit=2)
    message = str(err.value)
    assert message.startswith("pre-flight: one step of") and "no episode was run" in message
    assert (
        "server error: ValueError: request has no" in message
        and "observation/exterior_image_1_left" in message
    )
    assert not (tmp_path / "libero" / "episodes.jsonl").exists()

    # A server (openpi-server's own) whose policy answers 7-D actions: wrong shape, named.
    from openpi_server.websocket_policy_server import WebsocketPolicyServer

    class SevenDims:
        def infer(self, obs):
            return {"actions": np.zeros((5, 7), np.float32)}

    port = free_port()
    threading.Thread(
        target=WebsocketPolicyServer(SevenDims(), "127.0.0.1", port, {"name": "seven"}).serve_forever,
        daemon=True,
    ).start()
    for _ in range(50):
        try:
            urllib.request.urlopen(f"http://127.0.0.1:{port}/healthz", timeout=1)
            break
        except OSError:
            time.sleep(0.1)
    with pytest.raises(ValueError) as err:
        evaluate(tiny_benchmark, tmp_path / "seven", client(port), limit=1, workers=1)
    assert "answered actions of shape (5, 7)" in str(err.value) and "(H, 8)" in str(err.value)


def test_every_layout_carries_the_observation_there_and_back(env):
    from roboview.policies.serving.openpi_wire import wire_format
    from roboview.tasks.env import IMAGE_KEY, STATE_KEY

    obs, _ = env.reset(seed=5)
    cams = ("left_top", "wrist")
    custom = "img=camera:left_top,wrist_chw=camera_chw:wrist,q=state[0:7],g=state[7:8],text=instruction"
    for name, fmt in [(f, wire_format(f, cams)) for f in ("droid", "libero", "aloha")] + [
        ("custom", wire_format("custom", cams, custom))
    ]:
        request = fmt.encode(obs, "pick up the red cube")
        back, instruction = fmt.decode(request, env.image_size)
        assert instruction == "pick up the red cube", name
        np.testing.assert_array_equal(back[STATE_KEY], obs[STATE_KEY])
        for cam in cams:
            np.testing.assert_array_equal(back[IMAGE_KEY.format(cam)], obs[IMAGE_KEY.format(cam)])
    droid = wire_format("droid", cams).encode(obs, "x")
    assert droid["observation/joint_position"].shape == (7,) and droid[
        "observation/gripper_position"
    ].shape == (1,)
    assert droid["observation/exterior_image_1_left"].shape == (env.image_size, env.image_size, 3)
    aloha = wire_format("aloha", cams).encode(obs, "x")
    assert (
        set(aloha["images"]) == {"cam_high", "cam_left_wrist"} and aloha["images"]["cam_high"].shape[0] == 3
    )
    with pytest.raises(ValueError, match="unset"):  # a layout that leaves the gripper out cannot be decoded
        wire_format("custom", cams, "img=camera:left_top,q=state[0:7],p=instruction").decode(
            {"img": droid["observation/exterior_image_1_left"], "q": np.zeros(7), "p": "x"}, env.image_size
        )


def _thread_server(policy, metadata=None) -> int:
    from openpi_server.websocket_policy_server import WebsocketPolicyServer

    port = free_port()
    threading.Thread(
        target=WebsocketPolicyServer(policy, "127.0.0.1", port, metadata or {}).serve_forever, daemon=True
    ).start()
    for _ in range(100):
        try:
            urllib.request.urlopen(f"http://127.0.0.1:{port}/healthz", timeout=1)
            return port
        except OSError:
            time.sleep(0.05)
    raise AssertionError("openpi-server did not start")


def test_velocity_actions_integrate_the_gripper_binarizes_and_workers_spread_over_urls(
    tiny_benchmark, env, tmp_path
):
    from roboview.policies.base import AgentView

    class Velocity:  # openpi-server's policy interface: a chunk of 3 joint velocities (rad/s) + gripper 0.7
        def __init__(self):
            self.prompts = []

        def infer(self, obs):
            self.prompts.append(obs["prompt"])
            chunk = np.zeros((3, 8), np.float32)
            chunk[:, 0], chunk[:, 7] = 0.5, 0.7
            return {"actions": chunk}

    servers = [Velocity(), Velocity()]
    ports = [_thread_server(s) for s in servers]
    cfg = policy_config(
        "openpi",
        url=",".join(f"ws://127.0.0.1:{p}" for p in ports),
        cameras="left_top,wrist",
        image_size=env.image_size,
        action_space="joint_velocity",
        gripper="binary",
    )
    obs, _ = env.reset(seed=2)
    policy = cfg.build(AgentView.of(env))
    policy.reset(Episode.of(env, 2))
    action = policy.select_action(obs)
    expected = obs["observation.state"][:7].copy()
    expected[0] += 0.5 / env.fps  # one control period at 0.5 rad/s
    np.testing.assert_allclose(action[:7], expected, rtol=0, atol=1e-6)
    assert action[7] == 1.0
    policy.close()
    # Two URLs: the worker of rank i talks to server i (mod 2).
    from roboview.core.workers import set_worker_rank, worker_rank

    rank = worker_rank()
    try:
        for i in (1, 2):
            set_worker_rank(i)
            served = [len(s.prompts) for s in servers]
            policy = cfg.build(AgentView.of(env))
            policy.reset(Episode.of(env, 2))
            policy.select_action(obs)
            policy.close()
            assert [len(s.prompts) - n for s, n in zip(servers, served)] == [i % 2 == 0, i % 2 == 1]
    finally:
        set_worker_rank(rank)
    # Two spawned workers over the two URLs: every episode served, by whichever server its worker talks to.
    served = sum(len(s.prompts) for s in servers)
    evaluate(tiny_benchmark, tmp_path / "two", cfg, limit=4, workers=2, max_steps=3)
    assert sum(len(s.prompts) for s in servers) - served >= 4
    assert len(rows(tmp_path / "two")) == 4


def test_server_down_fails_before_any_rollout_naming_the_url():
    port = free_port()
    with pytest.raises(ValueError, match=rf"ws://127.0.0.1:{port}.*is it running"):
        client(port)
    with pytest.raises(ValueError, match="must start with ws://"):
        policy_config("openpi", url="http://127.0.0.1:8000")
    with pytest.raises(ValueError, match="obs_format"):
        policy_config("openpi", url=f"ws://127.0.0.1:{port}", obs_format="rlds")
    with pytest.raises(ValueError, match="state slices"):
        policy_config("openpi", url=f"ws://127.0.0.1:{port}", obs_format="custom", key_map="s=state[3:12]")


def test_a_server_killed_mid_run_stops_the_run_and_a_rerun_resumes(
    tiny_benchmark, tiny_checkpoint, reference, tmp_path
):
    port = free_port()
    server = start_server(tiny_checkpoint, port)
    out = tmp_path / "killed"
    journal = out / "episodes.jsonl"
    cfg = client(port, reconnects=1, reconnect_backoff_s=0.1)
    errors = []

    def go():
        try:
            evaluate(tiny_benchmark, out, cfg, splits="color,camera_pose", max_steps=6)
        except Exception as exc:  # noqa: BLE001  (the test reads it)
            errors.append(exc)

    thread = threading.Thread(target=go)
    thread.start()
    deadline = time.time() + 120
    while time.time() < deadline and (not journal.exists() or not journal.read_text().strip()):
        time.sleep(0.05)
    server.kill()  # SIGKILL: no goodbye frame
    server.wait()
    thread.join(timeout=120)
    assert len(errors) == 1 and isinstance(errors[0], PolicyUnavailable), errors
    assert f"ws://127.0.0.1:{port}" in str(errors[0]) and "rerun" in str(errors[0])
    done = [json.loads(line) for line in journal.read_text().splitlines()]
    # what finished is kept; nothing the kill cut short is recorded as a policy failure
    assert 1 <= len(done) < 4
    assert not any("closed the connection" in r["failure_reason"] for r in done)

    server = start_server(tiny_checkpoint, port)  # the same server back: the rerun finishes the rest
    try:
        evaluate(tiny_benchmark, out, cfg, splits="color,camera_pose", max_steps=6)
    finally:
        stop(server)
    resumed = rows(out)
    assert len(resumed) == 4 and not resumed.duplicated(["instance_id", "repeat"]).any()
    pd.testing.assert_frame_equal(
        resumed[COLS[:-2] + ["failure_reason"]], rows(reference)[COLS[:-2] + ["failure_reason"]]
    )


def test_openpi_client_against_serve_policy_batches_connections(tiny_benchmark, tiny_checkpoint):
    from openpi_client.websocket_client_policy import WebsocketClientPolicy

    from roboview.benchmark.format import load_benchmark
    from roboview.policies.lerobot_policy import LeRobotPolicy
    from roboview.policies.serving.openpi_wire import wire_format
    from roboview.tasks import make_env

    items = load_benchmark(tiny_benchmark, ["color"]).splits["color"][:4]
    env = make_env(cameras=("left_top", "wrist"), image_size=64)
    fmt = wire_format("droid", ("left_top", "wrist"))
    local = LeRobotPolicy(str(tiny_checkpoint), "cpu")
    requests, expected = [], []
    for seed, item in enumerate(items):
        obs, _ = env.reset(seed=seed, options={"instance": item.instance})
        local.reset(Episode.of(env, seed))
        expected.append(np.stack(local.predict_chunks({0: obs})[0]))
        requests.append(fmt.encode(obs, env.instruction))
    env.close()

    port = free_port()
    os.environ["ROBOVIEW_TEST_KEY"] = "s3cret"
    try:
        server = start_server(tiny_checkpoint, port, "--gather_ms=200", "--api_key_env=ROBOVIEW_TEST_KEY")
    finally:
        del os.environ["ROBOVIEW_TEST_KEY"]
    try:
        with pytest.raises(ValueError, match="401"):  # no key: refused before any rollout
            client(port)
        # openpi's own client, unchanged, with the key in openpi's Authorization header
        clients = [WebsocketClientPolicy("127.0.0.1", port, api_key="s3cret") for _ in range(4)]
        assert clients[0].get_server_metadata()["roboview"]["batched"] is True
        answers = [None] * 4
        barrier = threading.Barrier(4)

        def ask(i):
            barrier.wait()
            answers[i] = clients[i].infer(requests[i])["actions"]

        threads = [threading.Thread(target=ask, args=(i,)) for i in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=60)
    finally:
        summary = stop(server)
    for got, want in zip(answers, expected):
        assert got.shape == want.shape == (10, 8)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-4)
    assert not np.allclose(expected[0], expected[1])  # four episodes, four different chunks
    n_requests, n_passes = map(int, re.search(r"(\d+) requests in (\d+) forward passes", summary).groups())
    assert n_requests == 4 and n_passes < 4, summary  # several connections in one forward pass
