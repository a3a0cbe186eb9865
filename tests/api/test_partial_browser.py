"""A piece through the page in a real headless Chromium (issue 33): the hits show both partial scores,
and the 3D view of a hit colours the region of the model that the piece matched.

The screenshot docs/img/partial-region.png is refreshed from $SHAPEBAG_SCREENSHOTS by hand:
    cp results/screenshots/partial-region.png docs/img/partial-region.png
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from app.services import ingestion
from app.services.context import open_context
from app.storage import jobs as jobs_repo
from app.worker.runner import Worker
from tests.api.live import live_server
from tests.api.test_partial_api import DESCRIBE, _half, _obj, _shapes
from tests.api.test_web_browser import VIEWPORT, launch, needs_chromium, wait_until
from tests.conftest import make_settings

pytestmark = pytest.mark.slow  # a real browser: the second tier (make test-all)

REPO = Path(__file__).resolve().parents[2]
SHOTS = Path(os.environ.get("SHAPEBAG_SCREENSHOTS", REPO / "results" / "screenshots"))


def _pixels(path: Path) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGB")).astype(int)


def _orange(path: Path) -> float:
    """Share of the picture in the matched region's orange (red well above blue, some green)."""
    rgb = _pixels(path)
    return float(((rgb[..., 0] - rgb[..., 2] > 60) & (rgb[..., 1] > 40)).mean())


@needs_chromium
def test_a_piece_shows_both_scores_and_its_matched_region(tmp_path: Path) -> None:
    from playwright.sync_api import sync_playwright

    SHOTS.mkdir(parents=True, exist_ok=True)
    settings = make_settings(tmp_path / "data", describe=DESCRIBE)
    ctx = open_context(settings)
    for name, mesh in _shapes().items():
        ingestion.submit(ctx, _obj(mesh), f"{name}.obj", name=name, label=name)
    worker = Worker(ctx, "seed")
    worker.run_forever(exit_when_idle=True)
    with ctx.db.write() as conn:
        jobs_repo.enqueue(conn, "rebuild_vocabulary", payload={"size": 8})
    worker.run_forever(exit_when_idle=True)
    query = tmp_path / "half-quadruped.obj"
    query.write_bytes(_obj(_half(_shapes()["quadruped"])))

    with live_server(settings) as base, sync_playwright() as p:
        browser = launch(p)
        page = browser.new_page(viewport=VIEWPORT, device_scale_factor=1)
        page.goto(base + "/")
        page.set_input_files("#file", str(query))
        page.wait_for_selector("#search-results .card.hit", timeout=90_000)
        cards = page.locator("#search-results .card.hit")
        assert page.locator("#search-results .card.hit .name").first.text_content() == "quadruped"
        shares = page.locator("#search-results .card.hit .shares").all_text_contents()
        assert len(shares) == cards.count() and all("found" in s and "covers" in s for s in shares)

        cards.first.click()
        wait_until(page,
            "document.querySelectorAll('#search-results .view3d[data-rendered]').length === 2", timeout=60_000
        )
        assert page.input_value("#search-results .compare select.mode") == "region"
        assert "The query is a piece" in page.text_content("#search-results .compare .partial-why")
        page.wait_for_timeout(600)
        page.locator("#search-results .compare").screenshot(path=str(SHOTS / "partial-region.png"))
        hit_view = page.locator("#search-results .view3d").nth(1)
        hit_view.screenshot(path=str(tmp_path / "region.png"))
        page.locator("#search-results .compare input[type=checkbox]").uncheck()  # keypoints are red
        page.wait_for_timeout(300)
        hit_view.screenshot(path=str(tmp_path / "region-bare.png"))
        page.select_option("#search-results .compare select.mode", "plain")
        page.wait_for_timeout(300)
        hit_view.screenshot(path=str(tmp_path / "plain.png"))
        browser.close()
    region, plain = _orange(tmp_path / "region-bare.png"), _orange(tmp_path / "plain.png")
    assert region > 0.01 and plain < 0.001, (region, plain)
