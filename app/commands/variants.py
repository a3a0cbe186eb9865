"""`shapebag variants DIR`: the groups of meshes in a folder that are variants of one another (the same
model moved, rescaled, mirrored, re-exported, re-triangulated, or part of a plate), with the evidence.
No server and no data directory: the folder is read, nothing is written, nothing is deleted.

`shapebag variants backfill [--data-dir D]`: fingerprints and links for the stored models that have none
(stored before the variant step, or under an older fingerprint recipe); idempotent. (A folder that
happens to be called `backfill` is scanned as `./backfill`.)"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from app.cli import CommandError
from app.commands._common import add_data_dir, settings_from

BACKFILL = "backfill"


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("variants", help="group the meshes of a folder that are variants of each other")
    p.add_argument("folder", type=Path, help=f"folder of meshes (searched recursively), or `{BACKFILL}`:"
                   " fingerprint and link the data directory's models stored without")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.add_argument("--max-vertices", type=int, default=200_000, help="skip larger meshes (default 200000)")
    add_data_dir(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if str(args.folder) == BACKFILL:  # as typed: `./backfill` is a folder
        return _backfill(args)
    from app.core.mesh import InvalidMeshError, detect_format, load_mesh
    from app.core.variants import Prepared
    from app.core.variants.collection import find_pairs, groups

    if not args.folder.is_dir():
        raise CommandError(f"{args.folder} is not a folder")
    names, items, skipped = [], [], []
    for path in sorted(p for p in args.folder.rglob("*") if p.is_file()):
        rel = path.relative_to(args.folder).as_posix()
        try:
            detect_format(path.name)
        except InvalidMeshError:
            continue  # not a mesh file (labels.csv, textures, .bin buffers)
        try:
            mesh = load_mesh(path, max_vertices=args.max_vertices)
        except (InvalidMeshError, OSError) as exc:
            skipped.append({"file": rel, "reason": str(exc)})
            continue
        names.append(rel)
        items.append(Prepared(mesh))
    pairs = find_pairs(items)
    found = groups(len(items), pairs)
    report = {
        "files": len(names),
        "groups": [
            {"members": [names[i] for i in g],
             "pairs": [{"a": names[i], "b": names[j], **ev.to_dict()} for i, j, ev in pairs if i in g]}
            for g in found
        ],
        "skipped": skipped,
    }
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        _print_table(report)
    return 0


def _backfill(args: argparse.Namespace) -> int:
    import sys

    from app.services import variants
    from app.services.context import open_context

    ctx = open_context(settings_from(args, must_exist=True))

    def progress(done: int, total: int, model_id: int) -> None:
        if not args.json:
            print(f"  {done}/{total}: model {model_id}", file=sys.stderr)

    report = variants.backfill(ctx, progress)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(f"{report['missing']} models without fingerprints (recipe {report['version']}),"
              f" {report['fingerprinted']} fingerprinted, {report['links']} variant links found,"
              f" {len(report['skipped'])} skipped")
        for s in report["skipped"]:
            print(f"skipped model {s['model_id']}: {s['reason']}")
    return 0


def _print_table(report: dict) -> None:
    skipped = f", {len(report['skipped'])} files skipped" if report["skipped"] else ""
    print(f"{report['files']} meshes read, {len(report['groups'])} groups of variants{skipped}")
    for n, group in enumerate(report["groups"], start=1):
        print(f"\ngroup {n}: {len(group['members'])} files")
        print(f"  {'relation':<15} {'conf':>5} {'chamfer':>8} {'hausdorff':>9} {'scale':>9}  a -> b")
        for p in group["pairs"]:
            extra = f" x{p['copies']}" if p["relation"] in ("part_of", "contains") and p["copies"] > 1 else ""
            print(f"  {p['relation'] + extra:<15} {p['confidence']:>5.2f} {p['chamfer']:>8.1e}"
                  f" {p['hausdorff']:>9.1e} {p['scale']:>9.4g}  {p['a']} -> {p['b']}")
    for s in report["skipped"]:
        print(f"skipped {s['file']}: {s['reason']}")
