"""The quick-start flow in a real headless Chromium (issue 14, "What it must show"): a fresh data
directory with no demo data, models uploaded, then through the page: upload a query, ranked hits whose
thumbnails all arrive (no blank card), the 3D viewer of query and hit side by side with the explanation,
and a search by a stored model that marks the hits sharing its label.

Screenshots are saved as artifacts in $SHAPEBAG_SCREENSHOTS (default results/screenshots, not committed);
docs/img/results-page.png (the README's) is refreshed from them by hand:
    cp results/screenshots/results.png docs/img/results-page.png
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from app.config import SHIPPED_VOCABULARY, DescribeSettings
from tests.api.live import live_server
from tests.api.test_web_browser import VIEWPORT, launch, needs_chromium, wait_until
from tests.conftest import make_settings, wait_for

REPO = Path(__file__).resolve().parents[2]
SHOTS = Path(os.environ.get("SHAPEBAG_SCREENSHOTS", REPO / "results" / "screenshots"))


def _upload_collection(base: str, corpus) -> None:  # type: ignore[no-untyped-def]
    import httpx

    with httpx.Client(base_url=base, timeout=60) as http:
        jobs = []
        for path, label in corpus.seeded:
            r = http.post("/models", files={"file": (path.name, path.read_bytes())},
                          data={"label": label, "name": f"{label}-{path.stem}"})
            assert r.status_code == 202, r.text
            jobs.append(r.json()["job_id"])

        def finished() -> bool:
            states = [http.get(f"/jobs/{j}").json()["status"] for j in jobs]
            assert "failed" not in states
            return all(s == "done" for s in states)

        wait_for(finished, timeout_s=240, interval_s=0.5)
        wait_for(lambda: http.get("/readyz").json()["checks"].get("indexed_models") == len(jobs), 60)


def _pixels(path: Path) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGB")).astype(int)


@pytest.mark.slow
@needs_chromium
def test_quick_start_upload_results_viewer_and_explanation(tmp_path: Path, corpus) -> None:
    from playwright.sync_api import sync_playwright

    SHOTS.mkdir(parents=True, exist_ok=True)
    # what a new user runs: the shipped vocabulary and the default describe settings, nothing seeded
    settings = make_settings(
        tmp_path / "data", default_vocabulary=SHIPPED_VOCABULARY, describe=DescribeSettings()
    )
    query, query_label = corpus.held_out[0]
    with live_server(settings) as base, sync_playwright() as p:
        _upload_collection(base, corpus)
        browser = launch(p)
        page = browser.new_page(viewport=VIEWPORT, device_scale_factor=1)
        page.goto(base + "/")
        page.set_input_files("#file", str(query))
        page.wait_for_selector("#search-results .card.hit", timeout=90_000)
        # a placeholder may show while a thumbnail renders; once done, none is pending and none is blank
        wait_until(page,
            "document.querySelectorAll('#search-results .thumb.pending').length === 0", timeout=90_000
        )
        cards = page.locator("#search-results .card.hit")
        assert cards.count() == min(10, len(corpus.seeded))
        assert page.locator("#search-results .thumb.failed").count() == 0
        widths = page.eval_on_selector_all("#search-results .card img", "l => l.map(i => i.naturalWidth)")
        assert len(widths) == cards.count() + 1 and min(widths) > 0  # the query's preview too
        labels = page.locator("#search-results .card.hit .chip").all_text_contents()
        assert query_label in labels[:5]  # its own class near the top (quality is measured elsewhere)
        page.screenshot(path=str(SHOTS / "results.png"))

        # the 3D viewer and why it matched, in the same tab, below the results, heading not under the bar
        pages_before = len(browser.contexts[0].pages)
        cards.first.click()
        page.wait_for_selector("#search-results .compare .view3d[data-rendered] canvas", timeout=90_000)
        wait_until(page,
            "document.querySelectorAll('#search-results .view3d[data-rendered]').length === 2", timeout=30_000
        )
        assert len(browser.contexts[0].pages) == pages_before
        rows = page.locator("#search-results .top-words tbody tr")
        assert rows.count() >= 5
        first_hit = page.locator("#search-results .card.hit .name").first.text_content()
        assert first_hit in page.text_content("#search-results .compare h3")
        assert page.locator("#search-results .histogram .bar-a").count() > 0
        page.wait_for_timeout(600)  # let the smooth scroll settle before measuring
        top = page.evaluate(
            "document.querySelector('#search-results .compare h3').getBoundingClientRect().top"
        )
        bar = page.evaluate("document.querySelector('.topbar').getBoundingClientRect().bottom")
        assert top >= bar, f"the sticky header ({bar}px) covers the heading ({top}px)"
        page.locator("#search-results .compare").screenshot(path=str(SHOTS / "viewer.png"))
        shot = page.locator("#search-results .view3d").first.screenshot(path=str(SHOTS / "viewer-query.png"))
        assert shot
        words_rgb = _pixels(SHOTS / "viewer-query.png")
        colours = {tuple(c) for c in (words_rgb[::4, ::4] // 32).reshape(-1, 3).tolist()}
        assert len(colours) > 12, "the 3D view shows no coloured shape"  # several word colours, shaded

        # plain colouring turns every vertex steel blue; what stays warm are the red keypoints, until hidden
        view = page.locator("#search-results .view3d").first
        page.select_option("#search-results .compare select.mode", "plain")
        page.wait_for_timeout(300)
        view.screenshot(path=str(tmp_path / "plain.png"))
        page.locator("#search-results .compare input[type=checkbox]").uncheck()
        page.wait_for_timeout(300)
        view.screenshot(path=str(tmp_path / "bare.png"))
        warm = lambda path: ((_pixels(path)[..., 0] - _pixels(path)[..., 2]) > 30).mean()  # noqa: E731
        words = warm(SHOTS / "viewer-query.png")
        plain, bare = warm(tmp_path / "plain.png"), warm(tmp_path / "bare.png")
        assert bare < 0.002 < plain and words - plain > 0.01, (words, plain, bare)  # warm words gone

        # a search by a stored model marks the hits that share its label, and says how many
        model_id = int(cards.first.get_attribute("data-model-id"))
        page.goto(f"{base}/#similar/{model_id}")
        page.wait_for_selector("#similar-results .card.hit", timeout=60_000)
        shared = page.text_content("#similar-results .shared") or ""
        marked = page.locator("#similar-results .card.hit .same-label").count()
        assert shared.startswith(f"{marked} of ") and marked >= 1
        page.screenshot(path=str(SHOTS / "similar.png"))
        browser.close()
    assert (SHOTS / "results.png").stat().st_size > 10_000
