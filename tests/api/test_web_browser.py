"""The web page in a real headless Chromium against the real service (uvicorn on a loopback port).

Needs Debian's chromium (`apt-get install -y chromium`); the test is skipped, saying so, only when no
chromium binary is found. The Python side is Playwright (a dev dependency) driving that binary: no
browser download.

Refresh the README picture against a running service (e.g. `make run`):
    python tests/api/test_web_browser.py http://127.0.0.1:8000 QUERY_MESH docs/img/results-page.png
"""

from __future__ import annotations

import os
import shutil
import socket
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

CHROMIUM = next((p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p), None)
CHROMIUM_ARGS = [  # no GPU, no sandbox as root, and no background calls to a network that is closed
    "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--disable-background-networking",
    "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-quic",
]
VIEWPORT = {"width": 1280, "height": 900}


def wait_until(page, expression: str, timeout: int = 30_000) -> None:  # type: ignore[no-untyped-def]
    """page.wait_for_function without its in-page eval, which the page's CSP (no 'unsafe-eval') refuses:
    poll page.evaluate, which runs over the DevTools protocol, outside the page's policy."""
    deadline = time.monotonic() + timeout / 1000
    while not page.evaluate(expression):
        if time.monotonic() > deadline:
            raise TimeoutError(f"{expression[:80]!r} not true within {timeout / 1000:g} s")
        page.wait_for_timeout(100)


def launch(playwright):  # type: ignore[no-untyped-def]
    return playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)


def capture_results(base_url: str, query: Path, screenshot: Path | None = None, k: int = 10) -> dict:
    """Open the page, upload `query`, wait for the ranked thumbnails; return what the page shows."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = launch(p)
        page = browser.new_page(viewport=VIEWPORT, device_scale_factor=1)
        page.goto(base_url + "/")
        page.select_option("#k", str(k))
        page.set_input_files("#file", str(query))
        page.wait_for_selector("#search-results .card.hit", timeout=90_000)
        try:
            wait_until(page,   # every thumbnail (and the query preview) decoded
                "[...document.querySelectorAll('#search-results img')]"
                ".every(i => i.complete && i.naturalWidth > 0)",
                timeout=60_000,
            )
        except Exception as exc:  # say which pictures are missing
            images = page.eval_on_selector_all(
                "#search-results img", "l => l.map(i => [i.src.slice(0, 60), i.complete, i.naturalWidth])"
            )
            raise AssertionError(f"thumbnails did not load: {images}") from exc
        shown = page.evaluate(
            """() => {
              const all = (sel) => [...document.querySelectorAll('#search-results ' + sel)];
              return {
                heading: document.querySelector('#search-results h2').textContent,
                timing: document.querySelector('#search-results .timing').textContent,
                ranks: all('.card.hit .rank').map(e => e.textContent),
                labels: all('.card.hit .chip').map(e => e.textContent),
                distances: all('.distance').map(e => e.textContent),
                ids: all('.card.hit').map(e => +e.dataset.modelId),
                images: all('img').map(i => i.naturalWidth),
                error_hidden: document.querySelector('#error').hidden,
              };
            }"""
        )
        if screenshot is not None:
            page.screenshot(path=str(screenshot), full_page=False)
        browser.close()
    return shown


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def served(data_dir: Path) -> Iterator[str]:
    """The real app (lifespan, worker, index over the seeded data dir) on a free loopback port."""
    import httpx
    import uvicorn

    from app.main import create_app
    from tests.conftest import make_settings, wait_for

    port = _free_port()
    server = uvicorn.Server(
        uvicorn.Config(create_app(make_settings(data_dir)), host="127.0.0.1", port=port, log_level="warning")
    )
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    base = f"http://127.0.0.1:{port}"

    def ready() -> bool:
        try:
            return httpx.get(base + "/readyz", timeout=2).status_code == 200
        except httpx.HTTPError:
            return False

    try:
        wait_for(ready, timeout_s=60)
        yield base
    finally:
        server.should_exit = True
        thread.join(timeout=30)


needs_chromium = pytest.mark.skipif(
    CHROMIUM is None, reason="no chromium binary on PATH (install Debian's: apt-get install -y chromium)"
)


@pytest.mark.slow
@needs_chromium
def test_upload_shows_ranked_thumbnails_with_labels_and_distances(
    served: str, corpus, tmp_path: Path
) -> None:
    import httpx

    query, _ = corpus.held_out[0]
    shot = Path(os.environ.get("SHAPEBAG_WEB_SCREENSHOT", tmp_path / "results.png"))  # keep it to look at
    shown = capture_results(served, query, shot, k=10)
    expected = httpx.post(
        served + "/search", files={"file": (query.name, query.read_bytes())}, data={"k": "10"}, timeout=60
    ).json()
    assert shown["error_hidden"]
    assert query.name in shown["heading"] and "described in" in shown["timing"]
    assert shown["ranks"] == [f"#{h['rank']}" for h in expected["data"]] and len(shown["ranks"]) == 10
    assert shown["ids"] == [h["model_id"] for h in expected["data"]]
    assert shown["labels"] == [h["label"] for h in expected["data"]]
    assert shown["distances"] == [f"L1 {h['distance']:.3f}" for h in expected["data"]]
    assert len(shown["images"]) == 11 and min(shown["images"]) == 256  # query preview + 10 thumbnails
    _assert_screenshot_shows_results(shot)


def _assert_screenshot_shows_results(path: Path) -> None:
    """The picture is the page with rendered shapes in it, not a blank or error page."""
    import numpy as np
    from PIL import Image

    rgb = np.asarray(Image.open(path).convert("RGB")).astype(int)
    assert rgb.shape[:2] == (VIEWPORT["height"], VIEWPORT["width"])
    # the renderer's steel blue (b > r + 40) covers a visible part of the page: the shapes are there
    shape_pixels = (rgb[..., 2] - rgb[..., 0] > 40) & (rgb[..., 2] > 120)
    assert shape_pixels.mean() > 0.02


@pytest.mark.slow
@needs_chromium
def test_browse_filter_similar_and_error_message(served: str, corpus) -> None:
    from playwright.sync_api import sync_playwright

    labels = sorted({label for _, label in corpus.seeded})
    with sync_playwright() as p:
        browser = launch(p)
        page = browser.new_page(viewport=VIEWPORT)
        page.goto(served + "/#browse")
        page.wait_for_selector("#grid .card.model")
        assert page.locator("#grid .card.model").count() == len(corpus.seeded)
        assert page.text_content("#page-info") == f"1–{len(corpus.seeded)} of {len(corpus.seeded)}"

        # label filter: only that label's models remain
        page.fill("#label-filter", labels[0])
        per_label = len(corpus.seeded) // len(labels)
        try:
            wait_until(page, f"$('page-info').textContent.endsWith(' of {per_label}')")
        except Exception as exc:
            shows = page.text_content("#page-info"), page.text_content("#error-text")
            raise AssertionError(f"filter {labels[0]!r}: the page shows {shows!r}") from exc
        chips = page.locator("#grid .card.model .chip").all_text_contents()
        assert chips and set(chips) == {labels[0]}

        # clicking a model shows its neighbours (itself excluded)
        first = page.locator("#grid .card.model").first
        model_id = int(first.get_attribute("data-model-id"))
        first.click()
        page.wait_for_selector("#similar-results .card.hit")
        ids = [int(x) for x in page.locator("#similar-results .card.hit").evaluate_all(
            "cards => cards.map(c => c.dataset.modelId)")]
        assert ids and model_id not in ids
        # from the bottom of a grid taller than the window, a click scrolls up to the similar models with
        # their heading below the sticky top bar, not under it
        page.set_viewport_size({"width": 1280, "height": 480})
        page.evaluate("window.scrollTo(0, document.body.scrollHeight)")
        last = page.locator("#grid .card.model").last
        name = last.locator(".name").text_content()
        last.click()
        page.wait_for_function(
            "(name) => document.querySelector('#similar-results .card.query .name')?.textContent === name",
            arg=name,
        )
        page.wait_for_timeout(800)  # let the smooth scroll settle before measuring
        top = page.evaluate("document.querySelector('#similar-results h2').getBoundingClientRect().top")
        bar = page.evaluate("document.querySelector('.topbar').getBoundingClientRect().bottom")
        assert top >= bar, f"the sticky header ({bar}px) covers the similar models' heading ({top}px)"
        page.set_viewport_size(VIEWPORT)

        # a broken upload: the API's message is shown, nothing else breaks
        page.click("#tab-search")
        broken = {"name": "broken.obj", "mimeType": "text/plain", "buffer": b"nonsense"}
        page.set_input_files("#file", files=[broken])
        page.wait_for_selector("#error:not([hidden])")
        message = page.text_content("#error-text")
        assert message.startswith("Search failed: ") and len(message) > len("Search failed: ") + 5
        assert page.locator("#search-results .card").count() == 0
        browser.close()


if __name__ == "__main__":
    base_url, query_file, out = sys.argv[1:4]
    t = time.perf_counter()
    result = capture_results(base_url.rstrip("/"), Path(query_file), Path(out))
    took = time.perf_counter() - t
    print(f"{len(result['ranks'])} results; labels {result['labels']}; {took:.1f} s -> {out}")
