"""A client pointed at a running server of the other protocol is told which it is, within seconds: never "cannot
reach", never a wait for a hello that does not come. Real servers on 127.0.0.1: openpi-server's
`WebsocketPolicyServer` and vla-eval's `serve_async`."""

import threading
import time

import numpy as np
import pytest

from roboview.policies.types import policy_config
from tests.helpers.servers import free_port, joint_server, serving

pytestmark = pytest.mark.slow


class Still:
    def infer(self, obs: dict) -> dict:
        return {"actions": np.zeros((5, 8), np.float32)}

    def reset(self) -> None:
        pass


@pytest.fixture(scope="module")
def openpi_url():
    from openpi_server.websocket_policy_server import WebsocketPolicyServer

    port = free_port()
    server = WebsocketPolicyServer(Still(), "127.0.0.1", port, {"policy": "still"})
    threading.Thread(target=server.serve_forever, daemon=True).start()
    time.sleep(0.5)
    return f"ws://127.0.0.1:{port}"


def test_a_vla_eval_client_at_an_openpi_server_is_told_to_use_openpi(openpi_url):
    start = time.monotonic()
    with pytest.raises(ValueError) as err:
        policy_config("vla_eval", url=openpi_url)
    assert "answered with openpi's metadata" in str(err.value) and "use --policy.type=openpi" in str(
        err.value
    )
    assert "cannot reach" not in str(err.value) and time.monotonic() - start < 5


def test_an_openpi_client_at_a_vla_eval_server_is_told_to_use_vla_eval():
    with serving(joint_server()) as url:
        start = time.monotonic()
        with pytest.raises(ValueError) as err:
            policy_config("openpi", url=url, cameras="left_top,wrist")
        elapsed = time.monotonic() - start
    assert "answered a vla-eval HELLO" in str(err.value) and "use --policy.type=vla_eval" in str(err.value)
    assert elapsed < 5, f"{elapsed:.1f} s"


def test_each_client_still_reaches_its_own_server(openpi_url):
    client = policy_config("openpi", url=openpi_url, cameras="left_top,wrist", control="joint")
    assert client.served_by()["metadata"] == {openpi_url: {"policy": "still"}}
    with serving(joint_server()) as url:
        assert policy_config("vla_eval", url=url).env_control() == "joint"
