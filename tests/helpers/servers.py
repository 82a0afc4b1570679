"""Real servers on 127.0.0.1 the tests start and stop: RoboView's `roboview-serve-policy` (openpi's protocol),
LeRobot's own async-inference policy server, and vla-eval's model servers (in a thread, or in a process of their own
where a test must kill them). One launcher each, shared by every test that needs one."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from tests.helpers import ROOT, cli


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def start_server(checkpoint: Path, port: int, *flags: str) -> cli.Run | subprocess.Popen:
    """roboview.pipelines.serve_policy around a LeRobot checkpoint, in its own process (a fork of the preloaded
    server, tests/helpers/cli.py); returns once /healthz answers."""
    proc = cli.start(
        "roboview.pipelines.serve_policy",
        "--policy.type=lerobot",
        f"--policy.path={checkpoint}",
        f"--port={port}",
        "--threads=1",
        *flags,
        merge=True,
    )
    deadline = time.time() + 120
    while time.time() < deadline:
        try:
            if urllib.request.urlopen(f"http://127.0.0.1:{port}/healthz", timeout=1).read() == b"OK\n":
                return proc
        except OSError:
            time.sleep(0.3)
        if proc.poll() is not None:
            raise AssertionError(proc.communicate()[0])
    proc.kill()
    raise AssertionError("serve_policy did not come up within 120 s")


def stop(proc: cli.Run | subprocess.Popen) -> str:
    """SIGTERM, then what the server printed."""
    proc.send_signal(signal.SIGTERM)
    out, _ = proc.communicate(timeout=60)
    return out


class LeRobotServer:
    """`python -m lerobot.async_inference.policy_server` on 127.0.0.1:`port` (a free one by default; its logs/ folder
    goes to `cwd`), returned once it answers. `fresh`: a fresh interpreter (what it prints goes to `cwd`/server.log)
    instead of a fork of the preloaded server (tests/helpers/cli.py), for the tests that kill it mid-run: they expect
    the killed episode to be lost, and a fork answers again within the lerobot_async client's reconnects (8, from
    0.25 s), which then carries the episode on with the new server."""

    def __init__(
        self, cwd: Path, port: int | None = None, timeout_s: float = 120, fresh: bool = False
    ) -> None:
        from roboview.policies.lerobot_async_connection import check_reachable

        port = port or free_port()
        self.address = f"127.0.0.1:{port}"
        self.log = cwd / "server.log"
        args = [
            "--host=127.0.0.1",
            f"--port={port}",
            "--fps=10",
            "--inference_latency=0",
            "--obs_queue_timeout=2",
        ]
        env = os.environ | {"HF_HUB_OFFLINE": "1"}
        if fresh:
            with self.log.open("a") as log:
                self.proc = subprocess.Popen(
                    [sys.executable, "-m", "lerobot.async_inference.policy_server", *args],
                    cwd=cwd,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                    env=env,
                )
        else:
            self.proc = cli.start(
                "lerobot.async_inference.policy_server", *args, cwd=cwd, env=env, merge=True
            )
        deadline = time.time() + timeout_s
        while True:
            try:
                check_reachable(self.address, timeout_s=2)
                return
            except ValueError:
                if self.proc.poll() is not None or time.time() > deadline:
                    self.stop()
                    raise RuntimeError(f"policy server did not start: {self.printed()[-2000:]}") from None
                time.sleep(0.3)

    def printed(self) -> str:
        """What the server printed so far (a fork's output is read once it has ended)."""
        if isinstance(self.proc, cli.Run):
            return self.proc.output()[0]
        return self.log.read_text() if self.log.exists() else ""

    def kill(self) -> None:
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait()

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


# vla-eval: a model server answering a fixed action, declaring its specs (vla-eval's own PredictModelServer).
# A reachable arm pose (rad) and a closed gripper: RoboView's joint action.
POSE = np.array([0.3, -0.2, 0.1, -2.2, 0.05, 2.0, 0.6, 1.0], np.float32)


def fixed_server_class():
    """FixedServer, defined on first use (vla-eval is imported only by the tests that serve it)."""
    from vla_eval.model_servers.predict import PredictModelServer

    class FixedServer(PredictModelServer):
        """Answers `action` to every observation, declaring the given specs; records what it was sent."""

        def __init__(
            self, action, action_spec, observation_spec, params=None, fail_at=None, max_batch_size=1
        ):
            super().__init__(max_batch_size=max_batch_size)
            self.action, self.fail_at = np.asarray(action, np.float32), fail_at
            self.specs = action_spec, observation_spec
            self.params = params or {}
            self.starts, self.seen, self.batches = [], [], []

        def get_action_spec(self):
            return self.specs[0]

        def get_observation_spec(self):
            return self.specs[1]

        def get_observation_params(self):
            return self.params

        async def on_episode_start(self, config, ctx):
            self.starts.append(config["task"])
            await super().on_episode_start(config, ctx)

        def predict(self, obs, ctx):
            return self.predict_batch([obs], [ctx])[0]

        def predict_batch(self, obs_batch, ctx_batch):
            if self.max_batch_size > 1 and not self.batches:
                time.sleep(
                    0.3
                )  # the first batch is slow: the other connections' observations queue meanwhile
            self.batches.append(len(obs_batch))
            for obs, ctx in zip(obs_batch, ctx_batch):
                self.seen.append(obs)
                if self.fail_at is not None and ctx.step >= self.fail_at:
                    raise RuntimeError(f"model exploded at step {ctx.step}")
            return [{"actions": self.action.copy()} for _ in obs_batch]

    return FixedServer


def joint_server(**kw):
    """A FixedServer answering POSE as joint positions, reading the front camera, the joint state and the
    instruction."""
    from vla_eval.specs import GRIPPER_CLOSE_01, IMAGE_RGB, LANGUAGE, STATE_JOINT, DimSpec

    joints = {"joints": DimSpec("joints", 7, "joint_positions"), "gripper": GRIPPER_CLOSE_01}
    return fixed_server_class()(
        POSE,
        joints,
        {"front": IMAGE_RGB, "state": STATE_JOINT, "language": LANGUAGE},
        {"send_state": True},
        **kw,
    )


@contextmanager
def serving(model_server):
    """vla-eval's `serve_async` for `model_server` on a free loopback port, in a thread; yields its URL."""
    import anyio.from_thread
    from vla_eval.model_servers.serve import serve_async

    with anyio.from_thread.start_blocking_portal() as portal:
        future, port = portal.start_task(serve_async, model_server, "127.0.0.1", 0)
        try:
            yield f"ws://127.0.0.1:{port}"
        finally:
            future.cancel()


def start_vla_eval_server(port: int) -> subprocess.Popen:
    """`vla_eval.model_servers.serve.serve` of `joint_server()` in a process of its own, once it answers."""
    code = f"from vla_eval.model_servers.serve import serve; from tests.helpers.servers import joint_server; serve(joint_server(), '127.0.0.1', {port})"
    proc = subprocess.Popen(
        [sys.executable, "-c", code], cwd=ROOT, env=os.environ | {"PYTHONPATH": str(ROOT)}
    )
    deadline = time.time() + 60
    while time.time() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return proc
        except OSError:
            time.sleep(0.2)
    proc.kill()
    raise RuntimeError("vla-eval server did not start")
