"""Progress off a terminal: plain lines a log can keep, never tqdm's carriage returns (issue 14 item 9)."""

from __future__ import annotations

import io

from app.progress import LineProgress, progress


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_not_a_tty_writes_plain_lines_with_counts() -> None:
    out = io.StringIO()
    with progress(total=3, desc="describe", unit="mesh", file=out) as bar:
        for _ in range(3):
            bar.update()
    text = out.getvalue()
    assert "\r" not in text and "\x1b" not in text
    assert text.splitlines()[-1].startswith("describe: 3/3 mesh")


def test_lines_are_throttled_but_the_end_is_always_reported() -> None:
    out = io.StringIO()
    bar = LineProgress(total=100, desc="queue", unit="mesh", file=out, every_s=3600)
    for _ in range(99):
        bar.update()
    assert out.getvalue() == ""  # nothing due yet: no line per item
    bar.update()
    assert out.getvalue().count("\n") == 1 and out.getvalue().startswith("queue: 100/100 mesh")
    bar.close()
    assert out.getvalue().count("\n") == 1  # the count did not change: no repeated line


def test_set_postfix_and_assigned_n_as_ingest_uses_them() -> None:
    out = io.StringIO()
    with progress(total=4, desc="describe", unit="mesh", file=out) as bar:
        bar.n = 4
        bar.set_postfix(failed=1)
        bar.refresh()
    assert out.getvalue().splitlines() == [out.getvalue().splitlines()[0]]
    assert out.getvalue().startswith("describe: 4/4 mesh (failed=1)")


def test_iterating_yields_every_item_and_reports_the_total() -> None:
    out = io.StringIO()
    assert list(progress(range(5), desc="fit", file=out)) == [0, 1, 2, 3, 4]
    assert out.getvalue().startswith("fit: 5/5 it")


def test_a_terminal_gets_a_tqdm_bar() -> None:
    out = _Tty()
    with progress(total=2, desc="d", file=out) as bar:
        bar.update(2)
    assert type(bar).__name__ == "tqdm" and "\r" in out.getvalue()
