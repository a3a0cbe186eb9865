"""requirements/*.lock: the exact versions `make install`, the Dockerfile and CI install, with hashes.

pyproject.toml keeps the ranges a user's own install may take; the locks pin one version of each within
them (`make lock` writes them with uv). These tests fail when pyproject changes without `make lock`, when
the three locks disagree, and when this environment was not installed from the dev lock.
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

import pytest
from packaging.markers import Marker
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

REPO = Path(__file__).resolve().parents[1]
LOCKS = {name: REPO / "requirements" / f"{name}.lock" for name in ("base", "postgres", "dev")}
PIN = re.compile(r"^([A-Za-z0-9][A-Za-z0-9._-]*)==([^\s;\\]+)\s*(?:;\s*([^\\]+?))?\s*\\?$")


@dataclass(frozen=True)
class Pin:
    name: str  # canonical
    version: str
    marker: str | None
    hashes: int

    def applies(self) -> bool:
        return self.marker is None or Marker(self.marker).evaluate()


def read_lock(path: Path) -> dict[str, Pin]:
    """{canonical name: Pin} of a `uv pip compile --generate-hashes` file."""
    pins: dict[str, Pin] = {}
    current: tuple[str, str, str | None] | None = None
    hashes = 0

    def flush() -> None:
        if current is not None:
            name, version, marker = current
            pins[name] = Pin(name, version, marker, hashes)

    for line in path.read_text().splitlines():
        found = PIN.match(line)
        if found:
            flush()
            current, hashes = (canonicalize_name(found[1]), found[2], found[3]), 0
        elif line.strip().startswith("--hash=sha256:"):
            hashes += 1
    flush()
    return pins


def project() -> dict:
    return tomllib.loads((REPO / "pyproject.toml").read_text())["project"]


def requirements(extras: tuple[str, ...]) -> list[Requirement]:
    """pyproject's dependencies plus those of `extras`, self-references (shapebag[...]) expanded."""
    p, out, todo, seen = project(), [], list(extras), set()
    out += [Requirement(r) for r in p["dependencies"]]
    while todo:
        extra = todo.pop()
        if extra in seen:
            continue
        seen.add(extra)
        for text in p["optional-dependencies"][extra]:
            req = Requirement(text)
            if canonicalize_name(req.name) == "shapebag":
                todo += sorted(req.extras)
            else:
                out.append(req)
    return out


EXTRAS = {"base": (), "postgres": ("postgres",), "dev": ("dev",)}


@pytest.mark.parametrize("lock", sorted(LOCKS))
def test_every_dependency_of_pyproject_is_locked_within_its_range_with_hashes(lock: str) -> None:
    pins = read_lock(LOCKS[lock])
    assert pins, f"{LOCKS[lock]} lists no pinned distribution"
    for req in requirements(EXTRAS[lock]):
        pin = pins.get(canonicalize_name(req.name))
        assert pin is not None, f"{req.name} is in pyproject.toml but not in {lock}.lock: run make lock"
        assert req.specifier.contains(pin.version, prereleases=True), (
            f"{lock}.lock pins {pin.name}=={pin.version} outside pyproject's {req}: run make lock"
        )
    unhashed = sorted(p.name for p in pins.values() if p.hashes == 0)
    assert not unhashed, f"no hash for {unhashed} in {lock}.lock (pip --require-hashes would refuse it)"


def test_the_locks_agree_so_the_image_runs_the_versions_the_tests_ran() -> None:
    base, postgres, dev = (read_lock(LOCKS[n]) for n in ("base", "postgres", "dev"))
    for small, large, names in ((base, postgres, "base/postgres"), (postgres, dev, "postgres/dev")):
        differ = {n: (p.version, large[n].version if n in large else None)
                  for n, p in small.items() if n not in large or large[n].version != p.version}
        assert not differ, f"{names} locks disagree (name: (smaller, larger)): {differ}"


def test_this_environment_has_exactly_the_locked_versions() -> None:
    wrong = {}
    for pin in read_lock(LOCKS["dev"]).values():
        if not pin.applies():
            continue
        try:
            installed = metadata.version(pin.name)
        except metadata.PackageNotFoundError:
            installed = None
        if installed is None or Version(installed) != Version(pin.version):
            wrong[pin.name] = (pin.version, installed)
    assert not wrong, f"(locked, installed) differ: {wrong}; `make install` installs requirements/dev.lock"
