"""`shapebag vocabulary fit|rebuild|show`: make a frozen vocabulary, refit the service's, inspect it."""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from app.cli import CommandError
from app.commands._common import add_data_dir, settings_from, setup_logging


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("vocabulary", help="fit, rebuild or show geometric vocabularies")
    sub = p.add_subparsers(dest="action", required=True)

    fit = sub.add_parser("fit", help="fit a vocabulary on folders of meshes and save it (no data dir needed)")
    fit.add_argument("directory", type=Path, nargs="+",
                     help="folders of meshes (labels are not needed: a labels.csv, if any, lists the files)")
    fit.add_argument(
        "--out", type=Path, required=True, help="new directory for centers.npy + vocabulary.json"
    )
    _fit_options(fit)
    fit.add_argument("--processes", type=int, default=None, help="describing processes (default: cores)")
    fit.set_defaults(func=run_fit)

    rebuild = sub.add_parser("rebuild", help="refit the service's vocabulary on its stored descriptions")
    add_data_dir(rebuild)
    _fit_options(rebuild)
    rebuild.add_argument("--no-wait", action="store_true", help="only queue the job")
    rebuild.set_defaults(func=run_rebuild)

    show = sub.add_parser("show", help="the active vocabulary and every version")
    add_data_dir(show)
    show.set_defaults(func=run_show)


def _fit_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--size", type=int, default=64, help="number of words (default 64)")
    p.add_argument("--run", default="run5", help="descriptor selection, Table 1 (default run5)")
    p.add_argument("--seed", type=int, default=0, help="k-means seed")
    p.add_argument(
        "--fusion-weight", type=float, default=None,
        help="weight w of the Shape-DNA in the fused distance BoF/s_bof + w·DNA/s_dna, fixed with the "
        "vocabulary (default: app.core.fusion.DEFAULT_WEIGHT)",
    )


def run_fit(args: argparse.Namespace) -> int:
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context

    from threadpoolctl import threadpool_limits

    from app.core.fusion import DEFAULT_WEIGHT
    from app.core.vocabulary import Vocabulary
    from app.datasets.folder import DatasetError, read_mesh_folder
    from app.progress import progress
    from app.services.query_pool import describe_bytes
    from app.worker.processes import pin_threads

    if args.out.exists():
        raise CommandError(f"{args.out} exists: vocabularies are immutable, choose a new directory")
    settings = settings_from(args)
    try:
        items = [item for directory in args.directory for item in read_mesh_folder(directory)]
    except DatasetError as exc:
        raise CommandError(str(exc)) from exc
    params = settings.describe.params()
    processes = args.processes or os.cpu_count() or 1
    descriptions = []
    with ProcessPoolExecutor(processes, mp_context=get_context("spawn"), initializer=pin_threads) as pool:
        futures = [
            pool.submit(describe_bytes, i.path.read_bytes(), i.path.suffix, params, settings.max_vertices)
            for i in items
        ]
        for item, fut in progress(
            zip(items, futures, strict=True), total=len(items), desc="describe", unit="mesh"
        ):
            try:
                descriptions.append(fut.result()[0])
            except ValueError as exc:  # InvalidMeshError, UnsupportedFormatError: skip the mesh, say so
                print(f"  skipped {item.path}: {exc}")
    if not descriptions:
        raise CommandError("no mesh could be described")
    meta = {
        "source": " + ".join(Path(d).name for d in args.directory),
        "meshes": len(descriptions),
        "describe": params.fingerprint(),
        "command": f"shapebag vocabulary fit {' '.join(map(str, args.directory))} --size {args.size} "
        f"--run {args.run} "
        f"--seed {args.seed}",
    }
    weight = DEFAULT_WEIGHT if args.fusion_weight is None else args.fusion_weight
    meta["command"] += f" --fusion-weight {weight}"
    try:
        # one thread: k-means sums its clusters in per-thread chunks, so the thread count would move the
        # centres in the last digits (the describing processes above are pinned the same way)
        with threadpool_limits(1):
            vocab = Vocabulary.fit(descriptions, size=args.size, run=args.run, seed=args.seed, metadata=meta)
            # the fusion scales: BoF under the encode settings in force, Shape-DNA, of these same shapes
            vocab = vocab.with_fusion(descriptions, settings.encode.params(), weight)
    except ValueError as exc:
        raise CommandError(str(exc)) from exc
    vocab.save(args.out)
    s = vocab.fusion
    fused = f"; fusion scales BoF {s.bof:.4g}, Shape-DNA {s.dna:.4g} ({s.count}), w {s.weight:g}" if s else ""
    print(
        f"saved {vocab.size} words ({vocab.run}, trained on {vocab.metadata['trained_on_descriptors']} "
        f"descriptors of {len(descriptions)} meshes) to {args.out}{fused}"
    )
    return 0


def run_rebuild(args: argparse.Namespace) -> int:
    from app.core.descriptor import RUNS
    from app.services import bulk
    from app.services.context import open_context
    from app.storage import jobs as jobs_repo
    from app.worker.runner import Worker

    setup_logging()
    if args.run not in RUNS:
        raise CommandError(f"--run must be one of {', '.join(RUNS)}")
    ctx = open_context(settings_from(args))
    with ctx.db.write() as conn:
        pending = jobs_repo.pending(conn, "rebuild_vocabulary")
        job_id = (
            pending.id
            if pending
            else jobs_repo.enqueue(
                conn, "rebuild_vocabulary",
                payload={
                    "size": args.size, "run": args.run, "seed": args.seed, "fusion_weight": args.fusion_weight
                },
            )
        )
    print(f"vocabulary rebuild: job {job_id}")
    if args.no_wait:
        return 0
    worker = Worker(ctx, f"cli-{os.getpid()}")
    while True:  # help with the queue (a server's workers may take the job too) until ours finishes
        with ctx.db.read() as conn:
            job = jobs_repo.get(conn, job_id)
        assert job is not None
        if job.state in ("done", "failed"):
            break
        if worker.run_once() is None:
            bulk.wait_for_jobs(ctx, [job_id])
    if job.state == "failed":
        raise CommandError(f"the rebuild failed: {job.error}")
    print(f"done: {json.dumps(job.timings)}")
    return 0


def run_show(args: argparse.Namespace) -> int:
    from app.services.context import open_context
    from app.services.refit import refit_status
    from app.storage import vocabularies as vocab_repo

    ctx = open_context(settings_from(args, must_exist=True))
    with ctx.db.read() as conn:
        versions = vocab_repo.all_versions(conn)
    if not versions:
        print("no vocabulary yet: `shapebag vocabulary rebuild` once models are ingested")
        return 0
    for v in versions:
        mark = "*" if v.active else " "
        fusion = v.metadata.get("fusion")
        fused = f" + Shape-DNA ({fusion['count']} eigenvalues, weight {fusion['weight']:g})" if fusion else ""
        print(
            f"{mark} v{v.id}: {v.size} words{fused}, {v.run}, trained on {v.trained_on} descriptors, "
            f"created {v.created_at}, {v.path}"
        )
    ready, due = refit_status(ctx)
    if due is None:
        print("refit on the collection: off (SHAPEBAG_VOCABULARY_REFIT_AT=0)")
    else:
        print(f"refit on the collection: next at {due} ready models ({ready} now)")
    return 0
