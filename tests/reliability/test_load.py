"""Bounded load on loopback: 50 concurrent clients, searches and uploads mixed, no errors.

The default run lasts 12 s; `python -m benchmarks.load` runs the full 60 s and prints the same figures."""

from __future__ import annotations

import asyncio

import pytest

from benchmarks.load import Meshes, drive, report
from tests.reliability.helpers import start_server

pytestmark = pytest.mark.slow
SECONDS = 12.0


def test_fifty_clients_mixed_load_without_errors(data_dir, corpus, tmp_path):
    # admission control is tested in test_query_pool / test_uploads_held; here every request is let
    # in (queue and upload caps above the 50 clients) to see that they are all answered, in bounded time
    server, base = start_server(
        data_dir,
        tmp_path / "s.log",
        SHAPEBAG_WORKERS="1",
        SHAPEBAG_QUEUE_LIMIT="100000",
        SHAPEBAG_SEARCH_QUEUE="128",  # one client may hold half a queue: 64, above the 50 clients
        SHAPEBAG_CHECK_BUDGET__QUEUE="128",
        SHAPEBAG_MAX_CONCURRENT_UPLOADS="64",
        SHAPEBAG_CLIENT_REQUESTS="64",  # the 50 clients share one address: one client to the server
        SHAPEBAG_CLIENT_UPLOADS="64",  # ... and one client's share of the body slots
    )
    try:
        meshes = Meshes([p for p, _ in corpus.files])
        result = asyncio.run(drive(base, meshes, clients=50, seconds=SECONDS, upload_share=0.2))
    finally:
        server.stop()
    print("\n" + report(result))
    assert result["errors"] == 0, result["error_samples"]
    assert result["search"]["shed"] == result["upload"]["shed"] == 0
    assert result["search"]["requests"] >= 10 and result["upload"]["requests"] >= 3
    # bounded: every request answered, none anywhere near the client timeout
    assert result["search"]["max_s"] < 120 and result["upload"]["max_s"] < 120
