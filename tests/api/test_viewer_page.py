"""The page's viewer assets without a browser: same-origin imports only, the API contract they use,
and the layout rules issue 14 asked for (placeholder thumbnails, same tab, heading clear of the bar)."""

from __future__ import annotations

import re
from pathlib import Path

STATIC = Path(__file__).resolve().parents[2] / "app" / "api" / "static"


def test_viewer_imports_only_the_vendored_three() -> None:
    js = (STATIC / "viewer.js").read_text()
    imports = re.findall(r'import[^"\']*["\']([^"\']+)["\']', js)
    assert imports == ["/static/vendor/three.min.js"]
    assert (STATIC / "vendor" / "three.min.js").is_file()
    fetched = js.replace('"http://www.w3.org/2000/svg"', "")  # a namespace name, never fetched
    assert "http:" not in fetched and "https:" not in fetched


def test_page_asks_the_explain_api_and_opens_hits_in_the_same_tab() -> None:
    app = (STATIC / "app.js").read_text()
    needles = ("/explain?against=", '"/explain"', 'import("/static/viewer.js")', "hashchange")
    needles += ("clearInterval(ticker)",)  # the elapsed-seconds ticker stops with the search
    for needle in needles:
        assert needle in app, needle
    assert "window.open" not in app and "_blank" not in app
    html = (STATIC / "index.html").read_text()
    assert html.count('target="_blank"') <= 1  # only the API docs link


def test_styles_keep_headings_clear_of_the_sticky_bar_and_show_a_placeholder() -> None:
    css = (STATIC / "style.css").read_text()
    assert "scroll-margin-top" in css and ".thumb.pending::after" in css and ".thumb.failed::after" in css
    # every container app.js scrolls into view carries the margin, not only what it holds (Browse -> click
    # scrolled #similar-results itself, whose heading then slid under the bar)
    app = (STATIC / "app.js").read_text()
    within_one_function = (r'const out = \$\("([\w-]+)"\);'  # out = $("id") ... out.scrollIntoView
                           r"(?:(?!\nasync function|\nfunction).)*?out\.scrollIntoView")
    scrolled = set(re.findall(within_one_function, app, re.S))
    assert "similar-results" in scrolled
    rule = next(block for block in re.findall(r"([^{}]+)\{[^}]*scroll-margin-top", css))
    selectors = {sel.strip() for sel in rule.split(",")}
    assert {f"#{name}" for name in scrolled} <= selectors, (scrolled, selectors)
    assert "var(--topbar-height" in css and "--topbar-height" in app  # the bar's real height, not a guess
