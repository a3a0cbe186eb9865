"""Property-based tests of every documented operation against a real server (schemathesis, bounded):
no 5xx, and responses that conform to the OpenAPI schema (status codes, content types, bodies).

Driven through schemathesis' Python API with hypothesis `given` per operation (its pytest plugin does
not run under pytest 9)."""

from __future__ import annotations

import shutil

import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings
from schemathesis.checks import not_a_server_error
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    response_schema_conformance,
    status_code_conformance,
)

from tests.reliability.helpers import start_server

pytestmark = pytest.mark.slow
MAX_EXAMPLES = 25  # per operation (15 operations): well under a minute on 2 busy cores
CHECKS = [not_a_server_error, status_code_conformance, content_type_conformance, response_schema_conformance]
TOKEN = "reliability-secret-kkkkkkkkkkkkk"


def _runner(op, label: str, tried: dict[str, int], statuses: dict[int, int]):
    @given(case=op.as_strategy())
    @settings(
        max_examples=MAX_EXAMPLES,
        deadline=None,
        suppress_health_check=list(HealthCheck),
        derandomize=True,
        database=None,
    )
    def run(case):
        tried[label] += 1
        headers = {"X-Admin-Token": TOKEN} if case.path.startswith("/admin") else None
        response = case.call_and_validate(headers=headers, checks=CHECKS, timeout=60)
        statuses[response.status_code] = statuses.get(response.status_code, 0) + 1

    return run


def test_every_operation_conforms_to_the_schema(seeded_dir, tmp_path):
    data = shutil.copytree(seeded_dir, tmp_path / "data")
    server, base = start_server(data, tmp_path / "server.log", SHAPEBAG_WORKERS="1")
    failures: list[str] = []
    tried: dict[str, int] = {}
    statuses: dict[int, int] = {}
    try:
        schema = schemathesis.openapi.from_url(f"{base}/openapi.json")
        for result in schema.get_all_operations():
            op = result.ok()
            label = f"{op.method.upper()} {op.path}"
            tried[label] = 0

            run = _runner(op, label, tried, statuses)
            try:
                run()
            except Exception as exc:  # one line per failing operation, all operations still run
                failures.append(f"{label}: {type(exc).__name__}: {str(exc).strip()[:600]}")
    finally:
        server.stop()
    print(
        f"schemathesis: {sum(tried.values())} cases over {len(tried)} operations;",
        f"statuses {sorted(statuses.items())}",
    )
    assert (
        len(tried) >= 10 and any(200 <= s < 300 for s in statuses) and any(400 <= s < 500 for s in statuses)
    )
    assert not failures, "\n\n".join(failures)
