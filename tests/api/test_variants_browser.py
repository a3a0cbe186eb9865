"""The Variants view in a real headless Chromium: a model's variants above its similar models, the
relation on the hit, both shapes in 3D on a click, and a reviewer's decision recorded."""

from __future__ import annotations

import pytest
import trimesh

from tests.api.test_web_browser import CHROMIUM, launch, served, wait_until  # noqa: F401 (fixture)
from tests.conftest import wait_for

pytestmark = [
    pytest.mark.slow,  # a real browser: the second tier (make test-all)
    pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary (apt-get install -y chromium)"),
]


def test_variants_view_shows_the_relation_and_records_a_decision(served: str, corpus) -> None:  # noqa: F811
    import httpx
    from playwright.sync_api import sync_playwright

    path, _ = corpus.held_out[0]
    copy = trimesh.load(path, process=False)
    copy.apply_scale(25.4)
    ids = []
    for name, data in ((path.name, path.read_bytes()), ("inches.stl", copy.export(file_type="stl"))):
        r = httpx.post(served + "/models", files={"file": (name, data)}, timeout=60)
        ids.append(r.json()["model_id"])
        job = r.json()["job_id"]
        wait_for(lambda job=job: httpx.get(f"{served}/jobs/{job}").json()["state"] == "done", timeout_s=120)
    a, b = ids
    with sync_playwright() as p:
        browser = launch(p)
        page = browser.new_page()
        page.goto(f"{served}/#similar/{a}")
        page.wait_for_selector("#similar-results .results.variants .card", timeout=60_000)
        card = page.locator("#similar-results .results.variants .card").first
        assert "rescaled" in card.text_content() and "× 25.40" in card.text_content()
        card.locator("button", has_text="keep both").click()
        wait_until(  # not page.wait_for_function: the page's CSP refuses its in-page eval
            page,
            "document.querySelector('#similar-results .results.variants .decision')?.textContent"
            " === 'keep both'",
        )
        card.click()  # both shapes side by side, in the compare panel under the results
        page.wait_for_selector("#similar-results .compare:not([hidden])", timeout=60_000)
        browser.close()
    decision = httpx.get(f"{served}/models/{a}/variants").json()["data"][0]["decision"]
    assert decision["decision"] == "keep_both" and decision["other_id"] == b
