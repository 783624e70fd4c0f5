"""How `driftlab serve` serves: its connections send small responses at once (no Nagle delay), and its request
handlers run on as many threads as the settings say."""

import asyncio
import socket

import anyio.to_thread
import pytest

from driftlab.cli.serve import listening_socket
from driftlab.core.errors import ConfigError
from tests.server.conftest import in_process_client


def test_the_servers_connections_have_nagle_off():
    """asyncio sets TCP_NODELAY only on sockets created as IPPROTO_TCP; without it each keep-alive response's body
    waited ~40 ms for the client's delayed ACK."""
    sock = listening_socket("127.0.0.1", 0)
    port = sock.getsockname()[1]
    seen: list[int] = []

    async def main():
        async def accepted(reader, writer):
            seen.append(writer.get_extra_info("socket").getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY))
            writer.close()

        server = await asyncio.start_server(accepted, sock=sock)
        async with server:
            _, writer = await asyncio.open_connection("127.0.0.1", port)
            for _ in range(100):
                if seen:
                    break
                await asyncio.sleep(0.01)
            writer.close()

    asyncio.run(main())
    assert seen and seen[0] != 0


def test_a_taken_port_is_refused_naming_it():
    first = listening_socket("127.0.0.1", 0)
    with pytest.raises(ConfigError, match=f"--port {first.getsockname()[1]}"):
        listening_socket("127.0.0.1", first.getsockname()[1])
    first.close()


def test_request_handlers_run_on_the_configured_number_of_threads(tmp_path):
    async def tokens():
        return anyio.to_thread.current_default_thread_limiter().total_tokens

    with in_process_client(tmp_path / "threads.db", request_threads=3) as client:
        assert client.portal.call(tokens) == 3
