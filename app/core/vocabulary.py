"""Geometric vocabulary (k-means) and Bag of Features encoding (the paper's eqs. 5–8).

A Vocabulary is frozen once fit: its centres and metadata are saved as a plain .npy + .json pair
(never pickle) and versioned by the service.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from sklearn.cluster import KMeans

from app.core.baselines import SHAPE_DNA_COUNT
from app.core.descriptor import DEFAULT_RUN, dimension, select
from app.core.fusion import DEFAULT_WEIGHT, FusionScales, dna_vector, fit_scales, fuse
from app.core.pipeline import DescribeParams, ShapeDescription, fingerprint_fields
from app.core.spectrum import first_nonzero

VOCABULARY_FORMAT = 1


ENCODING_FIELDS = ("mode", "sigma_scale", "keypoints_only", "area_weighted")  # what encoding() may record


@dataclass(frozen=True)
class EncodeParams:
    """How a description becomes a BoF vector.

    mode           : "soft" (eq. 5, the default) or "hard" (eq. 6, the paper's choice). Soft is the default
                     because it held on every dataset we measured: a descriptor near the border of two
                     words no longer flips between them with the triangulation or the noise
                     (docs/results.md)
    sigma_scale    : soft VQ width σ, as a multiple of the vocabulary's typical quantisation distance (the
                     median distance of its training descriptors to their word)
    keypoints_only : integrate over the filtered keypoints instead of all vertices (eq. 8)
    area_weighted  : weight each vertex by its lumped area: eq. 7, F = ∫ θ dμ, the default (the same
                     surface gives the same F however its vertices are spread); False: each vertex
                     by 1 (eq. 8)
    normalize      : divide F by the total weight, so F does not depend on the vertex count
    fusion         : append the scaled Shape-DNA (app.core.fusion) when the vocabulary has fusion
                     scales; a vocabulary without them (older ones) always gives the pure BoF
    """

    mode: str = "soft"
    sigma_scale: float = 1.0
    keypoints_only: bool = False
    area_weighted: bool = True
    normalize: bool = True
    fusion: bool = True

    def encoding(self) -> dict:
        """The settings that change a BoF's distances (recorded with a vocabulary's fusion scale)."""
        encoded = {
            "mode": self.mode, "keypoints_only": self.keypoints_only, "area_weighted": self.area_weighted
        }
        if self.mode == "soft":  # σ changes soft BoFs only
            encoded["sigma_scale"] = self.sigma_scale
        return encoded

    def with_encoding(self, encoded: dict) -> EncodeParams:
        """These params with the settings a recorded encoding() names (the others kept)."""
        return replace(self, **{k: encoded[k] for k in ENCODING_FIELDS if k in encoded})



@dataclass(frozen=True)
class Vocabulary:
    """centers : (v, d) float32 geometric words; metadata says how they were made."""

    centers: np.ndarray
    run: str = DEFAULT_RUN
    sigma: float = 1.0  # median distance of training descriptors to their word
    metadata: dict = field(default_factory=dict)

    @property
    def size(self) -> int:
        """v, the number of words (the BoF part of a vector)."""
        return int(self.centers.shape[0])

    @property
    def fusion(self) -> FusionScales | None:
        """The Shape-DNA fusion scales fixed when this vocabulary was made, if any."""
        raw = self.metadata.get("fusion")
        return FusionScales.from_dict(raw) if raw else None

    def fused(self, params: EncodeParams | None = None) -> bool:
        """Whether encode() appends the Shape-DNA under `params`."""
        return (params or EncodeParams()).fusion and self.fusion is not None

    def dimension(self, params: EncodeParams | None = None) -> int:
        """Length of the vectors encode() gives under `params`: v, or v + c when fused (index size)."""
        scales = self.fusion
        return self.size + (scales.count if scales is not None and self.fused(params) else 0)

    def fusion_encoding_changes(self, params: EncodeParams) -> dict:
        """{setting: (fit, now)} where `params` encode otherwise than the BoFs the fusion scale was fit
        on ({} without fusion scales or a recorded encoding: nothing to compare)."""
        fitted = self.metadata.get("encode")
        if self.fusion is None or not isinstance(fitted, dict):
            return {}
        now = params.encoding()
        return {k: (fitted[k], now[k]) for k in now if k in fitted and fitted[k] != now[k]}

    def describe_changes(self, params: DescribeParams) -> dict:
        """{parameter: (fit, now)} where `params` describe otherwise than the shapes the words were fit
        on ({} when the fit recorded no describe parameters: a rebuild fits on whatever is stored)."""
        fitted = self.metadata.get("describe")
        if not isinstance(fitted, str):
            return {}
        old, new = fingerprint_fields(fitted), fingerprint_fields(params.fingerprint())
        return {k: (old.get(k, "?"), new.get(k, "?")) for k in sorted(old.keys() | new.keys())
                if old.get(k) != new.get(k)}

    def with_fusion(
        self, descriptions: Sequence[ShapeDescription], params: EncodeParams | None = None,
        weight: float = DEFAULT_WEIGHT,
    ) -> Vocabulary:
        """This vocabulary plus fusion scales fit on `descriptions` (its training shapes), their BoF
        encoded with `params`: the scales belong to the vocabulary, so stored vectors stay comparable."""
        if len(descriptions) < 2:
            raise ValueError("fusion scales need at least 2 training shapes")
        # c: as many eigenvalues as every training shape has (SHAPE_DNA_COUNT unless k is tiny); at
        # least 1, since first_nonzero raises SpectrumError for a shape with no non-zero eigenvalue
        available = min(len(d.eigenvalues) - first_nonzero(np.sort(d.eigenvalues)) for d in descriptions)
        count = min(SHAPE_DNA_COUNT, available)
        bofs = np.stack([self.bof(d, params) for d in descriptions])  # (N, v)
        dnas = np.stack([dna_vector(d, count) for d in descriptions])  # (N, c)
        scales = fit_scales(bofs, dnas, weight)
        # the BoF scale holds for BoFs encoded this way only (area-weighted ones have another median)
        encoded = (params or EncodeParams()).encoding()
        return replace(self, metadata=dict(self.metadata, fusion=scales.to_dict(), encode=encoded))

    @classmethod
    def fit(
        cls,
        descriptions: Sequence[ShapeDescription],
        size: int = 64,
        run: str = DEFAULT_RUN,
        seed: int = 0,
        keypoints_only: bool = True,
        metadata: dict | None = None,
    ) -> Vocabulary:
        """k-means over the p(x) of the keypoints (or of every vertex) of `descriptions`."""
        feats = training_features(descriptions, run, keypoints_only)
        return cls.fit_features(feats, size=size, run=run, seed=seed, metadata=metadata)

    @classmethod
    def fit_features(
        cls, features: np.ndarray, size: int = 64, run: str = DEFAULT_RUN, seed: int = 0,
        metadata: dict | None = None,
    ) -> Vocabulary:
        """features : (N, d) -> Vocabulary of `size` words."""
        features = np.asarray(features, dtype=np.float64)
        if features.ndim != 2 or features.shape[1] != dimension(run):
            raise ValueError(f"features must be (N, {dimension(run)}) for {run}, got {features.shape}")
        unique = np.unique(features.round(12), axis=0).shape[0]
        if unique < size:
            raise ValueError(f"{unique} distinct descriptors cannot make {size} words")
        km = KMeans(n_clusters=size, n_init=4, random_state=seed).fit(features)
        centers = km.cluster_centers_.astype(np.float32)
        dist = np.linalg.norm(features - km.cluster_centers_[km.labels_], axis=1)
        sigma = float(np.median(dist)) or float(dist.mean()) or 1.0
        meta = {
            "format": VOCABULARY_FORMAT,
            "size": size,
            "run": run,
            "dimension": dimension(run),
            "trained_on_descriptors": int(features.shape[0]),
            "seed": seed,
            "inertia": float(km.inertia_),
            "created_at": datetime.now(UTC).isoformat(timespec="seconds"),
        }
        meta.update(metadata or {})
        return cls(centers=centers, run=run, sigma=sigma, metadata=meta)

    def encode(self, description: ShapeDescription, params: EncodeParams | None = None) -> np.ndarray:
        """(dimension(params),) float32: the BoF F(X) (v,), fused with the Shape-DNA (v + c,) when
        the vocabulary has fusion scales and params.fusion is on."""
        params = params or EncodeParams()
        bof = self.bof(description, params)
        scales = self.fusion
        if scales is None or not params.fusion:
            return bof
        return fuse(bof, dna_vector(description, scales.count), scales)

    def bof(self, description: ShapeDescription, params: EncodeParams | None = None) -> np.ndarray:
        """(v,) float32 BoF vector F(X) of one shape (eqs. 7-8)."""
        params = params or EncodeParams()
        p = select(description.hks, self.run)  # (n, d)
        weights = description.weights.astype(np.float64) if params.area_weighted else np.ones(len(p))
        if params.keypoints_only:
            p, weights = p[description.keypoints], weights[description.keypoints]
        theta = self.quantize(p, params)  # (n, v)
        bof = weights @ theta  # eq. 8: Σ_x w(x) θ(x)
        if params.normalize and weights.sum() > 0:
            bof = bof / weights.sum()
        return bof.astype(np.float32)

    def quantize(self, p: np.ndarray, params: EncodeParams | None = None) -> np.ndarray:
        """(n, d) descriptors -> (n, v) feature distributions θ(x), rows summing to 1."""
        params = params or EncodeParams()
        sq = _squared_distances(p, self.centers)  # (n, v)
        if params.mode == "hard":  # eq. 6
            theta = np.zeros_like(sq)
            theta[np.arange(len(sq)), sq.argmin(axis=1)] = 1.0
            return theta
        if params.mode == "soft":  # eq. 5, normalised to sum 1 per vertex
            sigma = params.sigma_scale * self.sigma
            logits = -(sq - sq.min(axis=1, keepdims=True)) / (2.0 * sigma * sigma)
            theta = np.exp(logits)
            return theta / theta.sum(axis=1, keepdims=True)
        raise ValueError(f"unknown quantisation mode {params.mode!r}; use 'hard' or 'soft'")

    def save(self, directory: str | Path) -> Path:
        """Write centers.npy + vocabulary.json into `directory`, atomically (temp dir, then rename)."""
        directory = Path(directory)
        directory.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{directory.name}.", dir=directory.parent))
        tmp.chmod(0o755)  # mkdtemp makes it 0700: other users (a container's service user) must read it
        np.save(tmp / "centers.npy", self.centers, allow_pickle=False)
        meta = dict(self.metadata, run=self.run, sigma=self.sigma, size=self.size)
        (tmp / "vocabulary.json").write_text(json.dumps(meta, indent=2, sort_keys=True))
        for f in tmp.iterdir():
            with open(f, "rb") as fh:
                os.fsync(fh.fileno())
        if directory.exists():
            raise FileExistsError(f"{directory} exists: vocabularies are immutable")
        os.rename(tmp, directory)
        return directory

    @classmethod
    def load(cls, directory: str | Path) -> Vocabulary:
        directory = Path(directory)
        meta = json.loads((directory / "vocabulary.json").read_text())
        centers = np.load(directory / "centers.npy", allow_pickle=False).astype(np.float32)
        expected = (meta["size"], dimension(meta["run"]))
        if centers.shape != expected:
            raise ValueError(f"vocabulary at {directory} is inconsistent: centers {centers.shape}")
        if meta.get("fusion"):
            FusionScales.from_dict(meta["fusion"])  # a broken entry fails here, not at the first query
        return cls(centers=centers, run=meta["run"], sigma=float(meta["sigma"]), metadata=meta)

    def describe_meta(self) -> dict:
        return dict(self.metadata, run=self.run, sigma=self.sigma, size=self.size)


def training_features(
    descriptions: Sequence[ShapeDescription], run: str = DEFAULT_RUN, keypoints_only: bool = True
) -> np.ndarray:
    """(N, d) stacked p(x) of the keypoints (or all vertices) of every description."""
    parts = []
    for d in descriptions:
        p = select(d.hks, run)
        parts.append(p[d.keypoints] if keypoints_only else p)
    if not parts:
        raise ValueError("no descriptions to fit a vocabulary on")
    return np.concatenate(parts, axis=0)


def _squared_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n, d), (v, d) -> (n, v) squared Euclidean distances."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    sq = (a * a).sum(1)[:, None] - 2.0 * a @ b.T + (b * b).sum(1)[None, :]
    return np.maximum(sq, 0.0)


def l1_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """L1 (Manhattan) distances between BoF vectors or histograms (the D2 baseline's too):
    (n, v), (q, v) -> (n, q); eq. 9 with ‖·‖₁."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return np.abs(a[:, None, :] - b[None, :, :]).sum(axis=2)


def params_dict(params: EncodeParams) -> dict:
    return asdict(params)
