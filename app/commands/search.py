"""`shapebag search FILE`: ranked table of the models nearest to a mesh (local data dir or a server)."""

from __future__ import annotations

import argparse
from pathlib import Path

from app.cli import CommandError
from app.commands._common import add_data_dir, settings_from
from app.core.formats import SUPPORTED_FORMATS


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("search", help="rank stored models by L1 distance to a query mesh")
    p.add_argument("file", type=Path, help=f"query mesh ({', '.join(SUPPORTED_FORMATS)})")
    add_data_dir(p)
    p.add_argument("-k", type=int, default=10, help="how many results (default 10)")
    p.add_argument("--label", default=None, help="only models with this label")
    p.add_argument("--url", default=None, help="ask a running server instead (e.g. http://127.0.0.1:8000)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if not args.file.is_file():
        raise CommandError(f"{args.file} is not a file")
    hits, seconds = _remote(args) if args.url else _local(args)
    print(f"{'rank':>4}  {'distance':>9}  {'id':>6}  {'label':<14} name")
    for h in hits:
        print(
            f"{h['rank']:>4}  {h['distance']:>9.5f}  {h['model_id']:>6}  {str(h['label'] or '-'):<14}"
            f" {h['name']}"
        )
    print("seconds: " + ", ".join(f"{k} {v:.3f}" for k, v in seconds.items() if "." not in k))
    return 0


def _local(args: argparse.Namespace) -> tuple[list[dict], dict]:
    import time

    from app.core.mesh import InvalidMeshError
    from app.core.pipeline import describe
    from app.services import search
    from app.services.context import open_context
    from app.services.errors import ServiceError
    from app.services.live_index import LiveIndex
    from app.services.mesh_policy import load_upload

    ctx = open_context(settings_from(args, must_exist=True))  # never an empty database elsewhere
    t = time.perf_counter()
    try:
        mesh = load_upload(args.file, None, ctx.settings.max_vertices)
    except InvalidMeshError as exc:
        raise CommandError(f"{args.file}: {exc}") from exc
    description = describe(mesh, ctx.settings.describe.params())
    seconds = {"describe": time.perf_counter() - t}
    live = LiveIndex(ctx)
    live.refresh()
    try:
        result = search.search_description(ctx, live, description, args.k, args.label)
    except ServiceError as exc:
        raise CommandError(exc.message) from exc
    seconds.update(result.seconds)
    hits = [
        {
            "rank": h.rank,
            "distance": h.distance,
            "model_id": h.model.id,
            "label": h.model.label,
            "name": h.model.name,
        }
        for h in result.hits
    ]
    return hits, seconds


def _remote(args: argparse.Namespace) -> tuple[list[dict], dict]:
    import httpx

    data = {"k": str(args.k)} | ({"label": args.label} if args.label else {})
    try:
        r = httpx.post(
            f"{args.url.rstrip('/')}/search",
            files={"file": (args.file.name, args.file.read_bytes())},
            data=data,
            timeout=120,
        )
    except httpx.HTTPError as exc:
        raise CommandError(f"cannot reach {args.url}: {exc}") from exc
    if r.status_code != 200:
        raise CommandError(r.json().get("error", {}).get("message", r.text))
    body = r.json()
    return body["data"], body["seconds"]
