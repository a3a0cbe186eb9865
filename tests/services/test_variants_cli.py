"""`shapebag variants DIR`: groups of variants in a folder, table and JSON, nothing written."""

from __future__ import annotations

import json

import numpy as np
import trimesh

from app.cli import main


def _write_folder(root):
    points = np.random.default_rng(3).normal(size=(80, 3)) * [1.0, 0.6, 0.35]
    hull = trimesh.convex.convex_hull(points)
    hull.export(root / "part.stl")
    inches = hull.copy()
    inches.apply_scale(1 / 25.4)
    inches.export(root / "sub" / "part_inches.obj")
    mirror = hull.copy()
    mirror.apply_transform(np.diag([1.0, -1.0, 1.0, 1.0]))
    mirror.export(root / "part_mirror.ply")
    other = trimesh.convex.convex_hull(np.random.default_rng(4).normal(size=(80, 3)))
    other.export(root / "other.off")
    (root / "notes.txt").write_text("not a mesh")
    (root / "broken.stl").write_text("solid x\nendsolid x\n")


def test_variants_json_groups_the_same_part(tmp_path, capsys) -> None:
    (tmp_path / "sub").mkdir()
    _write_folder(tmp_path)
    before = sorted(p.name for p in tmp_path.rglob("*"))
    assert main(["variants", str(tmp_path), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["files"] == 4
    members = [g["members"] for g in report["groups"]]
    assert members == [["part.stl", "part_mirror.ply", "sub/part_inches.obj"]]
    relations = {(p["a"], p["b"]): p for p in report["groups"][0]["pairs"]}
    rescaled = relations[("part.stl", "sub/part_inches.obj")]
    assert rescaled["relation"] == "rescaled"
    assert abs(rescaled["scale"] - 1 / 25.4) < 1e-6
    assert relations[("part.stl", "part_mirror.ply")]["relation"] == "mirrored"
    assert [s["file"] for s in report["skipped"]] == ["broken.stl"]
    assert sorted(p.name for p in tmp_path.rglob("*")) == before  # nothing written, nothing deleted


def test_variants_table_and_a_missing_folder(tmp_path, capsys) -> None:
    (tmp_path / "sub").mkdir()
    _write_folder(tmp_path)
    assert main(["variants", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "1 groups of variants" in out and "rescaled" in out and "part.stl -> sub/part_inches.obj" in out
    assert main(["variants", str(tmp_path / "nope")]) == 2
    assert "is not a folder" in capsys.readouterr().err
