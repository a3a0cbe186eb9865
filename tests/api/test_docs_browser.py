"""/docs in a real headless Chromium that may reach nothing but the service (issue 14 item 3)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.api.live import live_server
from tests.api.test_web_browser import VIEWPORT, launch, needs_chromium
from tests.conftest import make_settings

pytestmark = pytest.mark.slow  # a real browser: the second tier (make test-all)


@needs_chromium
def test_swagger_ui_renders_with_every_external_request_blocked(tmp_path: Path) -> None:
    from playwright.sync_api import sync_playwright

    blocked: list[str] = []
    with live_server(make_settings(tmp_path / "data", workers=0)) as base, sync_playwright() as p:
        browser = launch(p)
        page = browser.new_page(viewport=VIEWPORT)

        def only_the_service(route) -> None:  # type: ignore[no-untyped-def]
            if route.request.url.startswith(base):
                route.continue_()
            else:
                blocked.append(route.request.url)
                route.abort()

        page.route("**/*", only_the_service)
        page.goto(base + "/docs")
        page.wait_for_selector(".swagger-ui .info .title", timeout=30_000)
        page.wait_for_selector(".opblock", timeout=30_000)
        title = page.text_content(".swagger-ui .info .title") or ""
        paths = page.locator(".opblock-summary-path").all_text_contents()
        browser.close()
    assert title.startswith("shapebag")
    assert "/search" in paths and "/models/{model_id}" in paths
    assert blocked == []  # it never even tried to leave
