"""The `lerobot_async` client's side of LeRobot's gRPC transport: the servers' addresses, a channel to one, the
reachability check made when the config is built, and what a failed call means (a lost connection, a timeout, the
server's own failure)."""

from __future__ import annotations

import re

ADDRESS = re.compile(r"^(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):(\d{1,5})$")
START_SERVER = (
    "python -m lerobot.async_inference.policy_server --host={host} --port={port} --fps=10 "
    "--inference_latency=0"
)


class ConnectionLost(Exception):
    """A call found the server unreachable (gRPC UNAVAILABLE) or cut off (CANCELLED)."""


def parse_servers(value: str) -> tuple[str, ...]:
    """`HOST:PORT` or a comma-separated list of them (worker i uses entry i mod n)."""
    servers = tuple(s.strip() for s in value.split(",") if s.strip())
    if not servers:
        raise ValueError(
            "give the LeRobot policy server as HOST:PORT (or a comma-separated list, one per worker)"
        )
    for server in servers:
        match = ADDRESS.match(server)
        if match is None or not 1 <= int(match.group(2)) <= 65535:
            raise ValueError(
                f"{server!r} is not HOST:PORT (e.g. 127.0.0.1:8080; a list: HOST:PORT,HOST:PORT)"
            )
    return servers


def open_channel(address: str):
    """(channel, AsyncInference stub) to the server at `address`, with LeRobot's own client options."""
    import grpc
    from lerobot.transport import services_pb2_grpc
    from lerobot.transport.utils import grpc_channel_options

    # lerobot's client options (4 MB, retries)
    channel = grpc.insecure_channel(address, grpc_channel_options())
    return channel, services_pb2_grpc.AsyncInferenceStub(channel)


def rpc_reason(exc: Exception) -> str:
    """A failed call in one phrase: the gRPC status and its details (else the exception)."""
    code, details = getattr(exc, "code", None), getattr(exc, "details", None)
    if callable(code) and callable(details):
        return f"{code().name}: {details()}"
    return f"{type(exc).__name__}: {exc}"


def start_server_hint(address: str) -> str:
    """What to check when the server at `address` does not answer: the command that starts it there."""
    host, _, port = address.rpartition(":")
    return (
        f"is the LeRobot policy server running there? Start it with `{START_SERVER.format(host=host, port=port)}` "
        "and check the address"
    )


def check_reachable(address: str, timeout_s: float) -> None:
    """`Ready` on the server at `address`; a ValueError naming it if it does not answer."""
    import grpc
    from lerobot.transport import services_pb2

    channel, stub = open_channel(address)
    try:
        stub.Ready(services_pb2.Empty(), timeout=timeout_s)
    except grpc.RpcError as exc:
        raise ValueError(
            f"the LeRobot policy server at {address} does not answer ({rpc_reason(exc)}); "
            f"{start_server_hint(address)}"
        ) from None
    finally:
        channel.close()


def chunk_error(exc, address: str, timeout_s: float) -> Exception:
    """A failed chunk request as a lost connection, a timeout (the evaluator retries) or the server's failure."""
    import grpc

    if exc.code() in (grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.CANCELLED):
        return ConnectionLost(rpc_reason(exc))
    if exc.code() == grpc.StatusCode.DEADLINE_EXCEEDED:
        return TimeoutError(
            f"no action chunk from the LeRobot policy server at {address} within "
            f"--policy.timeout_s={timeout_s:g} s"
        )
    return RuntimeError(f"the LeRobot policy server at {address} failed: {rpc_reason(exc)}")
