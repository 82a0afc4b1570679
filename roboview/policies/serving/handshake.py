"""Which protocol a websocket policy server speaks, read from its first frame, so that a client pointed at a server
of the other protocol says so within a second instead of calling it unreachable or waiting for a hello that never
comes.

An openpi server (`WebsocketPolicyServer`) sends one msgpack frame of metadata as soon as a client connects and then
waits for observations; a vla-eval model server sends nothing until the client's HELLO, and answers with a HELLO
message (`vla_eval.protocol.messages`: a msgpack map with `type`, `payload`, `seq`, `timestamp`).
"""

from __future__ import annotations

# How long a client waits for an openpi server's metadata before it asks, with a vla-eval HELLO, whether the server
# is one of vla-eval's.
PROBE_S = 1.0


class WrongProtocol(ConnectionError):
    """The server answered, in the other protocol."""


def is_vla_eval(frame: bytes | str) -> bool:
    """Whether `frame` is a vla-eval protocol message."""
    from vla_eval.protocol.messages import unpack_message

    if isinstance(frame, str):
        return False
    try:
        unpack_message(frame)
    except Exception:  # not a vla-eval message, whatever else it is
        return False
    return True


def is_openpi_metadata(frame: bytes | str) -> bool:
    """Whether `frame` is an openpi server's metadata: a msgpack map that is no vla-eval message."""
    from openpi_client import msgpack_numpy

    if isinstance(frame, str) or is_vla_eval(frame):
        return False
    try:
        return isinstance(msgpack_numpy.unpackb(frame), dict)
    except Exception:  # not msgpack
        return False


def hello_frame() -> bytes:
    """A vla-eval HELLO, as vla-eval's own clients open a session."""
    from vla_eval.protocol.messages import Message, MessageType, make_hello_payload, pack_message

    return pack_message(
        Message(type=MessageType.HELLO, payload=make_hello_payload(benchmark="roboview"), seq=1)
    )


def openpi_server(url: str) -> WrongProtocol:
    return WrongProtocol(
        f"the server at {url} answered with openpi's metadata: it is an openpi policy server, not a vla-eval model "
        "server; use --policy.type=openpi"
    )


def vla_eval_server(url: str) -> WrongProtocol:
    return WrongProtocol(
        f"the server at {url} sent no openpi metadata and answered a vla-eval HELLO: it is a vla-eval model server, "
        "not an openpi policy server; use --policy.type=vla_eval"
    )
