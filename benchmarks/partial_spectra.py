"""Partial matching from cached eigenpairs: try local-signature grids without a second eigen-solve.

    python -m benchmarks.partial_spectra cache SRC QUERIES... --out var/spec [--workers 2] [--every 2]
           [--classes a,b,c]
    python -m benchmarks.partial_spectra score SRC QUERIES --out var/spec [--rerank 100,200]
           [--classes a,b,c] [--set rim_factor=1.0 --set t0=0.004]

`cache` runs describe's stages up to the eigenpairs (canonical resolution, holes closed, Taubin, unit
area, Laplacian, k eigenpairs: app.core.pipeline) for every mesh of the labelled folders, and stores
eigenpairs (float32 vectors), lumped areas, vertices, faces and the rim mask (app.core.pipeline's: free
boundary and cap centres) as npz under --out, named <folder name>__<file with / as __>. `score` builds the
fused global vector (shipped vocabulary) and the local signature (LocalParams with --set changes) of
each, and prints, for QUERIES against SRC: global mAP / NN, the re-ranking of the global top N for each
N, and the calibration of forward / reverse against partial.csv's kept share. The signatures equal
describe()'s up to the float32 eigenvectors (docs/partial.md). Written for the shared 2 cores: caching
SHREC'11 and two bands (1800 meshes) took about 35 minutes, scoring 600 pieces with N = 200 about 40.
"""

from __future__ import annotations

import argparse
import csv
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

from app.core import hks as hks_mod
from app.core.laplacian import laplacian
from app.core.mesh import load_mesh
from app.core.partial import LocalParams, LocalSignature, local_signature
from app.core.partial_match import PartialMatch, match_many
from app.core.pipeline import LOCAL, DescribeParams, ShapeDescription, canonical_with_rim, smooth
from app.core.resolution import normalize_scale
from app.core.spectrum import Spectrum, smallest_eigenpairs
from app.core.vocabulary import Vocabulary
from app.datasets import locate
from app.datasets.folder import read_labelled_folder
from benchmarks.partial_rerank import VOCABULARY, average_precision


def _folder(name: str) -> Path:
    path = Path(name)
    return locate.require(name) if not path.is_dir() and name in locate.KNOWN else path


def _key(folder: Path, file: Path) -> str:
    return f"{folder.name}__" + file.relative_to(folder.resolve()).as_posix().replace("/", "__")


def _cache_one(job: tuple[str, str]) -> None:
    path, out = job
    if Path(out).exists():
        return
    params = DescribeParams()
    mesh = load_mesh(path)
    fine, rim = canonical_with_rim(mesh, params)
    work = normalize_scale(smooth(fine, mesh.n_vertices, params))
    stiffness, mass = laplacian(work.vertices, work.faces, params.laplacian)
    spectrum = smallest_eigenpairs(stiffness, mass, params.k)
    tmp = Path(out).with_suffix(".tmp.npz")
    np.savez(tmp, vals=spectrum.eigenvalues, vecs=spectrum.eigenvectors.astype(np.float32),
             mass=mass.diagonal().astype(np.float32), verts=work.vertices, faces=work.faces, rim=rim)
    tmp.rename(out)


def cache(folders: list[Path], out: Path, workers: int, every: int = 1,
          classes: set[str] | None = None) -> None:
    """Cache every mesh of the first folder (the models) and every `every`-th of the others (of
    `classes` only, when given; the every-th counts in the whole folder)."""
    out.mkdir(parents=True, exist_ok=True)
    jobs = [(str(r.path), str(out / f"{_key(f, r.path)}.npz"))
            for i, f in enumerate(folders) for r in read_labelled_folder(f)[::every if i else 1]
            if classes is None or r.label in classes]
    with ProcessPoolExecutor(workers) as pool:
        for i, _ in enumerate(pool.map(_cache_one, jobs, chunksize=4)):
            if i % 100 == 0:
                print(f"{i}/{len(jobs)}", flush=True)


def _load(path: Path, vocab: Vocabulary, params: LocalParams) -> tuple[np.ndarray, LocalSignature]:
    vec, local, _ = load_with_spectrum(path, vocab, params)
    return vec, local


def load_with_spectrum(path: Path, vocab: Vocabulary,
                       params: LocalParams) -> tuple[np.ndarray, LocalSignature, Spectrum]:
    """A cached entry -> (fused global vector (v,), local signature, its spectrum)."""
    z = np.load(path)
    spectrum = Spectrum(z["vals"], z["vecs"].astype(np.float64))
    times = hks_mod.time_scales(spectrum.eigenvalues, DescribeParams().m, DescribeParams().time_range)
    h = hks_mod.normalize(hks_mod.heat_kernel_signature(spectrum, times))
    desc = ShapeDescription(hks=h.astype(np.float32), weights=z["mass"], keypoints=np.zeros(len(h), bool),
                            eigenvalues=spectrum.eigenvalues, input_vertices=0)
    local = local_signature(spectrum, z["verts"], z["faces"], z["mass"], z["rim"], params)
    return vocab.encode(desc).astype(np.float64), local, spectrum


def score(src: Path, queries: Path, out: Path, reranks: list[int], classes: set[str] | None,
          params: LocalParams) -> None:
    vocab = Vocabulary.load(VOCABULARY)
    with open(queries / "partial.csv", newline="") as fh:
        kept = {row["file"]: float(row["kept_fraction"]) for row in csv.DictReader(fh)}
    rows = [r for r in read_labelled_folder(src) if classes is None or r.label in classes]
    qrows = [r for r in read_labelled_folder(queries) if classes is None or r.label in classes]
    models = [_load(out / f"{_key(src, r.path)}.npz", vocab, params) for r in rows]
    pieces = [_load(out / f"{_key(queries, r.path)}.npz", vocab, params) for r in qrows]
    labels = np.array([r.label for r in rows])
    names = [r.path.relative_to(src.resolve()).as_posix() for r in rows]
    mvec = np.stack([m[0] for m in models])
    deepest = max(reranks)
    ap: dict[int, list[float]] = {n: [] for n in [0, *reranks]}
    nn: dict[int, list[float]] = {n: [] for n in [0, *reranks]}
    own: list[tuple[float, PartialMatch]] = []
    for q, (vec, local) in zip(qrows, pieces, strict=True):
        order = np.argsort(np.abs(mvec - vec).sum(axis=1), kind="stable")
        total = int((labels == q.label).sum())
        top = order[:deepest]
        found = match_many(local, [models[j][1] for j in top], params)
        partial = np.array([m.distance for m in found])
        for n in [0, *reranks]:
            head = top[:n][np.argsort(partial[:n], kind="stable")] if n else top[:0]
            ranked = np.concatenate([head, order[n:]])
            ap[n].append(average_precision(labels[ranked], q.label, total))
            nn[n].append(float(labels[ranked[0]] == q.label))
        qname = q.path.relative_to(queries.resolve()).as_posix()
        own += [(kept[qname], m) for j, m in zip(top, found, strict=True) if names[j] == qname]
    print(f"{len(qrows)} pieces ({queries.name}) against {len(rows)} models, {len(set(labels))} classes; "
          f"{params}")
    for n in [0, *reranks]:
        name = "global" if n == 0 else f"re-rank {n}"
        print(f"  {name:11s} mAP {100 * np.mean(ap[n]):6.2f}  NN {np.mean(nn[n]):.3f}")
    if own:
        share = np.array([k for k, _ in own])
        fwd, rev = np.array([m.forward for _, m in own]), np.array([m.reverse for _, m in own])
        scale = np.array([m.scale for _, m in own])
        print(f"  own whole among the top {deepest}: {len(own)}/{len(qrows)}; kept {share.mean():.3f} "
              f"forward {fwd.mean():.3f} reverse {rev.mean():.3f} (corr {np.corrcoef(share, rev)[0, 1]:.3f}) "
              f"|scale - kept| {np.abs(scale - share).mean():.3f}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("command", choices=("cache", "score"))
    p.add_argument("folders", nargs="+", help="cache: folders to cache; score: SRC QUERIES")
    p.add_argument("--out", type=Path, default=Path("var/spec"))
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--every", type=int, default=1, help="cache: every n-th mesh of the query folders")
    p.add_argument("--rerank", default="100,200")
    p.add_argument("--classes", default="")
    p.add_argument("--set", action="append", default=[], help="a LocalParams field: name=value")
    a = p.parse_args(argv)
    folders = [_folder(f) for f in a.folders]
    if a.command == "cache":
        cache(folders, a.out, a.workers, a.every, set(a.classes.split(",")) if a.classes else None)
        return 0
    changes = {k: type(getattr(LOCAL, k))(float(v)) for k, v in (s.split("=", 1) for s in a.set)}
    score(folders[0], folders[1], a.out, [int(n) for n in a.rerank.split(",")],
          set(a.classes.split(",")) if a.classes else None, replace(LOCAL, **changes))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
