"""Progress reporting for long commands: a tqdm bar on a terminal, plain lines anywhere else.

tqdm redraws its bar with carriage returns, which a log file or CI console keeps as one long garbled line;
off a terminal we print "desc: n/total unit" lines instead, at most every `every_s` seconds and at the end.
Both expose the small part of tqdm's interface our commands use: update(), n, set_postfix(), refresh(),
iteration, and use as a context manager.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterable, Iterator
from typing import Any, TextIO


class LineProgress:
    """tqdm's interface, printed as one plain line per report (no carriage returns)."""

    def __init__(
        self,
        iterable: Iterable[Any] | None = None,
        total: int | None = None,
        desc: str = "",
        unit: str = "it",
        file: TextIO | None = None,
        every_s: float = 10.0,
        disable: bool = False,
    ) -> None:
        self.iterable = iterable
        self.total = total if total is not None else _len(iterable)
        self.desc, self.unit, self.every_s, self.disable = desc, unit, every_s, disable
        self.file = file or sys.stderr
        self.n = 0
        self._postfix = ""
        self._last_n = -1
        self._last_t = time.monotonic()
        self._start = self._last_t

    def __enter__(self) -> LineProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __iter__(self) -> Iterator[Any]:
        for item in self.iterable or ():
            yield item
            self.update()
        self.close()

    def update(self, n: int = 1) -> None:
        self.n += n
        self.refresh(final=False)

    def set_postfix(self, **values: Any) -> None:
        self._postfix = ", ".join(f"{k}={v}" for k, v in values.items())

    def refresh(self, final: bool = False) -> None:
        now = time.monotonic()
        done = self.total is not None and self.n >= self.total
        due = final or done or now - self._last_t >= self.every_s
        if self.disable or not due or self.n == self._last_n:
            return
        self._last_n, self._last_t = self.n, now
        of = f"/{self.total}" if self.total is not None else ""
        extra = f" ({self._postfix})" if self._postfix else ""
        seconds = now - self._start
        print(f"{self.desc}: {self.n}{of} {self.unit}{extra} [{seconds:.0f} s]", file=self.file, flush=True)

    def close(self) -> None:
        self.refresh(final=True)


def _len(iterable: Iterable[Any] | None) -> int | None:
    try:
        return len(iterable)  # type: ignore[arg-type]
    except TypeError:
        return None


def progress(iterable: Iterable[Any] | None = None, *, file: TextIO | None = None, **kwargs: Any) -> Any:
    """A tqdm bar when `file` (default stderr) is a terminal, else a LineProgress with the same arguments."""
    stream = file or sys.stderr
    if stream.isatty():
        from tqdm import tqdm

        return tqdm(iterable, file=stream, **kwargs)
    return LineProgress(iterable, file=stream, **kwargs)
