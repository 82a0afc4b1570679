"""Joining a Ray cluster, shared by the evaluator's Ray backend (roboview.eval.running.backends) and the builder's
(roboview.benchmark.build_ray): the address or a private local instance, EGL in every actor, and a token of its own
for a local instance so that nothing is written to ~/.ray."""

from __future__ import annotations

import os
from pathlib import Path


class ClusterLost(RuntimeError):
    """The Ray cluster's head stopped answering, or no node is left to run on."""


def connect(address: str | None, num_workers: int, flag: str = "--eval.ray_address") -> None:
    """Join the Ray cluster at `address`, or start a local Ray instance of `num_workers` CPUs; nothing when this
    process is connected already. ClusterLost when no cluster answers at `address`."""
    import ray

    if ray.is_initialized():
        return
    env = {"env_vars": {"MUJOCO_GL": "egl", "PYOPENGL_PLATFORM": "egl"}}
    if address:
        # Without its head the driver exits after this long (Ray's default, 60 s, only delays the exit: the
        # head watch has already stopped the run).
        os.environ.setdefault("RAY_gcs_rpc_server_reconnect_timeout_s", "15")
        try:
            ray.init(address=address, log_to_driver=False, runtime_env=env)
        except ConnectionError as exc:
            raise ClusterLost(
                f"no Ray cluster answers at {flag}={address} ({exc}); start one "
                "(ray start --head) or drop the flag to run a local Ray instance"
            ) from None
    else:
        # "local": a new instance of our own, never a cluster `ray start` left on this machine.
        private_token()
        ray.init(
            address="local",
            num_cpus=num_workers,
            include_dashboard=False,
            log_to_driver=False,
            runtime_env=env,
        )


def private_token() -> None:
    """A local Ray instance authenticates with a token of its own, in a private temporary file: Ray would otherwise
    write one to ~/.ray/auth_token, after which every `ray start` on the machine expects it (a cluster started
    without it then refuses its nodes with InvalidAuthToken). A token or mode the user set is left alone."""
    if {"RAY_AUTH_MODE", "RAY_AUTH_TOKEN", "RAY_AUTH_TOKEN_PATH"} & set(os.environ):
        return
    if (Path.home() / ".ray" / "auth_token").is_file():
        return  # the user's own token
    import atexit
    import secrets
    import shutil
    import tempfile

    folder = Path(tempfile.mkdtemp(prefix="roboview-ray-"))
    token = folder / "auth_token"
    token.write_text(secrets.token_hex(32))
    token.chmod(0o600)
    os.environ["RAY_AUTH_TOKEN_PATH"] = str(token)
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
