"""The real app (lifespan included) under uvicorn on a free loopback port, for browser tests."""

from __future__ import annotations

import contextlib
import socket
import threading
from collections.abc import Iterator

from app.config import Settings


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextlib.contextmanager
def live_server(settings: Settings) -> Iterator[str]:
    """Yields the base URL once /healthz answers; stops the server afterwards."""
    import httpx
    import uvicorn

    from app.main import create_app
    from tests.conftest import wait_for

    port = free_port()
    server = uvicorn.Server(
        uvicorn.Config(create_app(settings), host="127.0.0.1", port=port, log_level="warning")
    )
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    base = f"http://127.0.0.1:{port}"

    def up() -> bool:
        try:
            return httpx.get(base + "/healthz", timeout=2).status_code == 200
        except httpx.HTTPError:
            return False

    try:
        wait_for(up, timeout_s=60)
        yield base
    finally:
        server.should_exit = True
        thread.join(timeout=30)
