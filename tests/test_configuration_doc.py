"""docs/configuration.md lists every setting the code reads, under its real name and default, and no other.

The names are built from the Settings model as pydantic-settings builds them (env_prefix, then the
nested delimiter for each nested model), so a setting added to app/config.py without a row fails here.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest
from pydantic import BaseModel

from app.config import Settings

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "configuration.md"
PREFIX = Settings.model_config["env_prefix"]
DELIMITER = Settings.model_config["env_nested_delimiter"]
MENTION = re.compile(re.escape(PREFIX) + r"[A-Z0-9_]*")  # SHAPEBAG_DESCRIBE__ (a group) included
LITERAL = re.compile(r"""["'](""" + re.escape(PREFIX) + r"""[A-Z0-9_]+)["']""")
# defaults that depend on the machine or the install, not constants to copy into a table
MACHINE_DEFAULTS = {f"{PREFIX}WORKERS", f"{PREFIX}DEFAULT_VOCABULARY"}


def _nested_model(annotation: Any) -> type[BaseModel] | None:
    return annotation if isinstance(annotation, type) and issubclass(annotation, BaseModel) else None


def env_names(model: type[BaseModel] = Settings, prefix: str = PREFIX) -> dict[str, tuple[str, ...]]:
    """Every environment variable of `model`, nested models walked: name -> path of field names."""
    names: dict[str, tuple[str, ...]] = {}
    for field, info in model.model_fields.items():
        name = prefix + field.upper()
        nested = _nested_model(info.annotation)
        if nested is None:
            names[name] = (field,)
        else:
            for sub, path in env_names(nested, name + DELIMITER).items():
                names[sub] = (field, *path)
    return names


def names_read_outside_settings() -> set[str]:
    """SHAPEBAG_* names that app/ spells out as whole strings (os.environ reads such as
    app/datasets/locate.py's SHAPEBAG_DATASETS) and that are no Settings field."""
    found: set[str] = set()
    for source in (ROOT / "app").rglob("*.py"):
        found.update(LITERAL.findall(source.read_text(encoding="utf-8")))
    return found - set(env_names())


def _doc() -> str:
    return DOC.read_text(encoding="utf-8")


def _rows() -> dict[str, str]:
    """Variable name -> the default cell of the table row that names it (first cell)."""
    rows: dict[str, str] = {}
    for line in _doc().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("|") and len(cells) >= 3:
            for name in MENTION.findall(cells[0]):
                rows[name] = cells[1]
    return rows


def _formats(value: Any) -> set[str]:
    """How a default may be written in the table: `true`, `30` or `30.0`, `*(empty)*` ..."""
    if isinstance(value, bool):
        return {f"`{str(value).lower()}`"}
    if isinstance(value, float):
        return {f"`{value:g}`", f"`{value!r}`"}
    if isinstance(value, str) and not value:
        return {"*(empty)*"}
    if isinstance(value, list) and not value:
        return {"`[]`"}
    return {f"`{value}`"}


def test_the_walk_builds_the_names_pydantic_settings_reads(monkeypatch: pytest.MonkeyPatch) -> None:
    # the names this test checks are the ones the settings really read: set two, see them arrive
    monkeypatch.setenv(f"{PREFIX}STORAGE{DELIMITER}QUOTA_MB", "77")
    monkeypatch.setenv(f"{PREFIX}RENDER_BUDGET{DELIMITER}TIMEOUT_S", "3.5")
    names = env_names()
    settings = Settings()
    assert names[f"{PREFIX}STORAGE{DELIMITER}QUOTA_MB"] == ("storage", "quota_mb")
    assert settings.storage.quota_mb == 77 and settings.render_budget.timeout_s == 3.5
    assert f"{PREFIX}DATA_DIR" in names and f"{PREFIX}STORAGE" not in names  # leaves only


def test_every_setting_has_a_row() -> None:
    rows = _rows()
    missing = sorted(set(env_names()) - set(rows))
    assert not missing, f"docs/configuration.md has no table row for {', '.join(missing)}"


def test_the_settings_read_outside_the_model_have_a_row_too() -> None:
    outside = names_read_outside_settings()
    assert f"{PREFIX}DATASETS" in outside  # the scan sees app/datasets/locate.py
    missing = sorted(outside - set(_rows()))
    assert not missing, f"docs/configuration.md has no table row for {', '.join(missing)}"


def test_the_document_names_no_unknown_variable() -> None:
    known = set(env_names()) | names_read_outside_settings()
    unknown = set()
    for name in set(MENTION.findall(_doc())):
        if name.endswith("_"):  # a group (SHAPEBAG_DESCRIBE__*) or the prefix itself
            if not any(k.startswith(name) for k in known):
                unknown.add(name)
        elif name not in known:
            unknown.add(name)
    assert not unknown, f"docs/configuration.md names {', '.join(sorted(unknown))}, unknown to app/"


def test_each_row_gives_the_default_of_the_code(monkeypatch: pytest.MonkeyPatch) -> None:
    import os

    for var in [v for v in os.environ if v.startswith(PREFIX)]:
        monkeypatch.delenv(var)  # the defaults, not this shell's settings
    settings = Settings()
    rows = _rows()
    for name, path in env_names().items():
        if name in MACHINE_DEFAULTS or name not in rows:
            continue  # a missing row fails test_every_setting_has_a_row
        value: Any = settings
        for field in path:
            value = getattr(value, field)
        written = _formats(value)
        assert any(w in rows[name] for w in written), (
            f"{name}: the code's default is {value!r}, the table says {rows[name]!r}"
        )
