"""BoF + Shape-DNA fusion: one vector whose L1 distance is the fused distance.

The eigenvalues of every shape are computed anyway (the HKS needs them), so the beginning of the
spectrum (Shape-DNA, app.core.baselines) comes for free. The two distances live on different scales,
so each is divided by a scale fixed once, at vocabulary time, from the training shapes: the median
pairwise L1 distance of that part. With

    fuse(bof, dna) = [bof / s_bof,  w · dna / s_dna]        (v + c,)

the L1 distance of two fused vectors is L1(bof) / s_bof + w · L1(dna) / s_dna: an L1 index (FAISS
METRIC_L1) ranks by the fused distance with no re-ranking step, and a vocabulary that stores its
scales keeps every stored vector comparable with every later query.

Shape-DNA is compared with L1 here (Reuter used L2): the index has one metric, and on the normalised
λ_i·A/i every entry has the same order of magnitude, so L1 weighs them alike too.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np

from app.core.baselines import SHAPE_DNA_COUNT, shape_dna
from app.core.pipeline import ShapeDescription

# w: BoF + 1.0 × DNA, each over its median; fused, every collection measured did better (docs/results.md)
DEFAULT_WEIGHT = 1.0
MAX_PAIRS = 200_000  # above this many pairs, fit_scales draws this many (seeded) instead of all


def dna_vector(description: ShapeDescription, count: int = SHAPE_DNA_COUNT) -> np.ndarray:
    """(count,) float64 Shape-DNA λ_i / i of a description (its eigenvalues belong to the unit-area
    mesh, so the area factor is 1 and the vector does not depend on the mesh's scale)."""
    return shape_dna(description.eigenvalues, area=1.0, count=count)


@dataclass(frozen=True)
class FusionScales:
    """Fixed at vocabulary time, stored with it.

    bof    : s_bof, median pairwise L1 distance of the training shapes' BoF vectors
    dna    : s_dna, the same for their Shape-DNA vectors
    weight : w, the DNA part's weight in the fused distance
    count  : c, Shape-DNA length (eigenvalues used)
    """

    bof: float
    dna: float
    weight: float
    count: int = SHAPE_DNA_COUNT

    def __post_init__(self) -> None:
        if not (self.bof > 0 and self.dna > 0 and self.weight >= 0 and self.count >= 1):
            raise ValueError(f"fusion scales must be positive (weight >= 0, count >= 1): {self}")

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> FusionScales:
        return cls(
            bof=float(d["bof"]), dna=float(d["dna"]), weight=float(d["weight"]),
            count=int(d.get("count", SHAPE_DNA_COUNT)),
        )


def pairwise_l1(x: np.ndarray, max_pairs: int = MAX_PAIRS, seed: int = 0) -> np.ndarray:
    """(N, d) -> L1 distances over the pairs i < j, or over a seeded sample of `max_pairs` pairs
    (i != j) when there are more, so the result is deterministic."""
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[0]
    if n < 2:
        raise ValueError(f"a scale needs at least 2 shapes, got {n}")
    if n * (n - 1) // 2 <= max_pairs:
        i, j = np.triu_indices(n, k=1)
    else:
        rng = np.random.default_rng(seed)
        i = rng.integers(0, n, max_pairs)
        j = (i + rng.integers(1, n, max_pairs)) % n  # never i: no zero self-distances in the median
    return np.abs(x[i] - x[j]).sum(axis=1)


def typical_distance(x: np.ndarray) -> float:
    """(N, d) -> median pairwise L1 distance; its mean if the median is 0 (most pairs equal), else 1."""
    d = pairwise_l1(x)
    return float(np.median(d)) or float(d.mean()) or 1.0


def fit_scales(bofs: np.ndarray, dnas: np.ndarray, weight: float = DEFAULT_WEIGHT) -> FusionScales:
    """bofs (N, v), dnas (N, c) of the training shapes -> their scales (median pairwise L1 each)."""
    bofs, dnas = np.asarray(bofs), np.asarray(dnas)
    if bofs.ndim != 2 or dnas.ndim != 2 or bofs.shape[0] != dnas.shape[0]:
        raise ValueError(f"bofs (N, v) and dnas (N, c) must pair up, got {bofs.shape} and {dnas.shape}")
    return FusionScales(
        bof=typical_distance(bofs), dna=typical_distance(dnas), weight=float(weight), count=int(dnas.shape[1])
    )


def fuse(bof: np.ndarray, dna: np.ndarray, scales: FusionScales) -> np.ndarray:
    """bof (..., v), dna (..., c) -> (..., v + c) float32 [bof / s_bof, w · dna / s_dna]."""
    bof, dna = np.asarray(bof, dtype=np.float64), np.asarray(dna, dtype=np.float64)
    if dna.shape[-1] != scales.count:
        raise ValueError(f"Shape-DNA has {dna.shape[-1]} entries, the scales were fit on {scales.count}")
    parts = (bof / scales.bof, scales.weight * dna / scales.dna)
    return np.concatenate(parts, axis=-1).astype(np.float32)


# --- query-adaptive fusion: a re-rank of the candidates of the fused index -------------------------------
#
# A fixed weight cannot serve every collection: where the Shape-DNA is weak (open scans) any weight near 1
# costs the BoF's lead, and where a noisy query's BoF is misleading (its words moved, its spectrum did not)
# only the Shape-DNA finds its class. Each query is weighed by how well each part's nearest neighbours
# agree with the *other* part: the k nearest by BoF are a tight group in Shape-DNA distance when the BoF
# found the query's class, and the reverse. The weight then drives one step of query expansion
# (the query averaged with its m nearest), which pulls a noisy query's BoF back towards its class.
# A closed query never weighs its Shape-DNA less than the fixed fusion does: the spectrum of a closed
# surface has no boundary condition, while an open one's (a scan, a cut) moves with where the surface
# stops, so only an open query starts from the lower weight. A distinct nearest match (by the index's
# fused L1, well nearer than the second: Lowe's ratio test) stays first: the expansion reorders a
# query's class, and must not demote a copy of the query for looking unlike its neighbours.
# A closed query whose own mesh carries vertex noise (its normal displacements anti-correlated from vertex
# to vertex, app.core.roughness.displacement_correlation) weighs its Shape-DNA more still: the noise moves
# the HKS at every vertex, and so the BoF's words, while the first eigenvalues of a closed surface hardly
# move; the agreement ratio misses it when the noisy BoF lands in one wrong class, not in a scatter.


# each of the re-rank's two index searches returns this many (>= the service's largest k, so every answer
# comes from their union); the service (services/fusion_rerank) and the evaluation (evaluation/adaptive)
RERANK_CANDIDATES = 100


@dataclass(frozen=True)
class AdaptiveRule:
    """The query-adaptive re-rank (docs/results.md, issue 30).

    weight     : w0, the Shape-DNA weight when both parts agree (a BoF + w0 × DNA ranking)
    pivot      : τ, agreement ratio below which the Shape-DNA gains weight: w = w0 · max(1, τ / r)^p
    power      : p
    neighbours : k, each part's nearest neighbours whose agreement is measured
    expansion  : m, nearest candidates averaged into the query before the final ranking (0: none)
    closed_weight : the least weight of a closed query (the fixed fusion's weight, DEFAULT_WEIGHT)
    closed_rim : a query whose rim (free boundary length / √area, app.core.partial.rim_length) is at
                 most this is closed; the same rankings at 0 and 0.05 on every column (docs/results.md)
    distinct   : the index's nearest stays first when its fused L1 is below this share of the second
                 nearest's (0: never); 0.8, 0.9 and 0.95 rank every column alike (docs/results.md)
    noisy_below : a closed query whose input's displacement correlation is below this is noisy (clean
                  surfaces 0.6-0.9, vertex noise about -0.5, CAD creases 0.1-0.8: docs/results.md)
    noisy_weight : the least weight of a noisy closed query
    """

    weight: float = 0.4
    pivot: float = 0.9
    power: float = 3.0
    neighbours: int = 10
    expansion: int = 2
    closed_weight: float = DEFAULT_WEIGHT
    closed_rim: float = 0.05
    distinct: float = 0.9
    noisy_below: float = 0.0
    noisy_weight: float = 4.0

    def __post_init__(self) -> None:
        if not (self.weight > 0 and self.pivot > 0 and self.power >= 0 and self.neighbours >= 2
                and self.expansion >= 0 and self.closed_weight >= 0 and self.closed_rim >= 0
                and 0 <= self.distinct <= 1 and -1 <= self.noisy_below <= 1 and self.noisy_weight >= 0):
            raise ValueError(f"invalid adaptive fusion rule: {self}")


def split_parts(vectors: np.ndarray, words: int, stored_weight: float) -> tuple[np.ndarray, np.ndarray]:
    """Fused vectors (..., v + c) -> bof / s_bof (..., v), dna / s_dna (..., c): the stored weight undone."""
    if stored_weight <= 0:
        raise ValueError("the fused vectors carry no Shape-DNA part (weight 0)")
    vectors = np.asarray(vectors, dtype=np.float64)
    return vectors[..., :words], vectors[..., words:] / stored_weight


def _l1(query: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    return np.abs(vectors - query).sum(axis=-1)


def _spread(parts: np.ndarray, members: np.ndarray) -> float:
    """Mean L1 distance between the rows `members` of `parts` (n, d), over the ordered pairs i != j."""
    x = parts[members]
    k = len(x)
    return float(np.abs(x[:, None, :] - x[None, :, :]).sum()) / (k * (k - 1))


def agreement(b: np.ndarray, d: np.ndarray, bofs: np.ndarray, dnas: np.ndarray, k: int) -> float:
    """r = x_bof / x_dna for one query; b, d (n,) its part distances to n candidates, bofs (n, v),
    dnas (n, c) the candidates' parts.

    x_bof = spread in DNA of the DNA's k nearest / spread in DNA of the BoF's k nearest (1 when the BoF's
    neighbours are as tight a group to the Shape-DNA as its own), x_dna the same the other way round.
    r < 1: the Shape-DNA's neighbours look more like one class than the BoF's. 1 when undefined."""
    k = min(k, len(b))
    if k < 2:
        return 1.0
    near_b = np.argsort(b, kind="stable")[:k]
    near_d = np.argsort(d, kind="stable")[:k]
    spreads = (_spread(dnas, near_d), _spread(dnas, near_b), _spread(bofs, near_b), _spread(bofs, near_d))
    if min(spreads) <= 0:  # duplicates: no evidence either way
        return 1.0
    return (spreads[0] / spreads[1]) / (spreads[2] / spreads[3])


def is_closed(rim: float | None, rule: AdaptiveRule) -> bool:
    """Whether a query with this rim is closed; unknown (None, NaN: no local signature) is not."""
    return rim is not None and bool(rim <= rule.closed_rim)


def is_noisy(noise: float | None, rule: AdaptiveRule) -> bool:
    """Whether an input with this displacement correlation carries vertex noise; unknown is not."""
    return noise is not None and bool(noise < rule.noisy_below)


def query_weight(r: float, rule: AdaptiveRule, rim: float | None = None, noise: float | None = None) -> float:
    """w = w0 · max(1, τ / r)^p, at least closed_weight for a closed query and noisy_weight for a closed
    noisy one: the Shape-DNA's weight."""
    w = rule.weight * max(1.0, rule.pivot / r) ** rule.power
    if not is_closed(rim, rule):
        return w
    return max(w, rule.closed_weight, rule.noisy_weight if is_noisy(noise, rule) else 0.0)


def adaptive_query(
    query: np.ndarray, candidates: np.ndarray, words: int, stored_weight: float, rule: AdaptiveRule,
    rim: float | None = None, noise: float | None = None,
) -> tuple[float, np.ndarray]:
    """query (v + c,) fused, candidates (n, v + c) its nearest stored vectors (the query itself
    excluded), rim and noise (displacement correlation) the query's (None: unknown) -> (w, expanded
    query (v + c,) in the same fused layout)."""
    qb, qd = split_parts(query, words, stored_weight)
    cb, cd = split_parts(candidates, words, stored_weight)
    b, d = _l1(qb, cb), _l1(qd, cd)
    w = query_weight(agreement(b, d, cb, cd, rule.neighbours), rule, rim, noise)
    m = min(rule.expansion, len(b))
    if m == 0:
        return w, np.asarray(query, dtype=np.float32)
    near = np.argsort(b + w * d, kind="stable")[:m]
    expanded = (np.asarray(query, dtype=np.float64) + np.asarray(candidates, dtype=np.float64)[near].sum(0))
    return w, (expanded / (m + 1)).astype(np.float32)


def adaptive_distances(
    expanded: np.ndarray, w: float, vectors: np.ndarray, words: int, stored_weight: float
) -> np.ndarray:
    """(n,) L1(bof) / s_bof + w · L1(dna) / s_dna of the expanded query to vectors (n, v + c)."""
    qb, qd = split_parts(expanded, words, stored_weight)
    cb, cd = split_parts(vectors, words, stored_weight)
    return _l1(qb, cb) + w * _l1(qd, cd)


def adaptive_rerank(
    query: np.ndarray,
    search: Callable[[np.ndarray, int], np.ndarray],
    vectors_of: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    words: int, stored_weight: float, rule: AdaptiveRule, candidates: int, rim: float | None = None,
    noise: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The served re-rank: the fused index searched for the query's `candidates` nearest, the weight and
    the expanded query found among them, the index searched again for the expanded query, and the union
    of both answers ranked by adaptive_distances.

    query      : (v + c,) fused vector
    search     : (vector, n) -> ids (<= n,) of the n nearest by the index's fused L1 (the query's own
                 stored copy left out by the caller when it must be)
    vectors_of : ids (n,) -> (ids kept (n',), their stored fused vectors (n', v + c))
    rim        : the query's free boundary over √area (None: unknown, weighed as open)
    noise      : the query's input displacement correlation (None: unknown, weighed as clean)
    -> ids (u,) and their distances (u,), ascending (ties in id order) but for a distinct nearest
    match, which comes first with its own distance (distinct_first)."""
    ids, vectors = vectors_of(search(query, candidates))
    if len(ids) == 0:
        return np.zeros(0, np.int64), np.zeros(0)
    w, expanded = adaptive_query(query, vectors, words, stored_weight, rule, rim, noise)
    union, union_vectors = vectors_of(np.union1d(ids, search(expanded, candidates)))
    dist = adaptive_distances(expanded, w, union_vectors, words, stored_weight)
    order = np.argsort(dist, kind="stable")
    first = distinct_first(_l1(np.asarray(query, np.float64), np.asarray(vectors, np.float64)), rule.distinct)
    if first is not None and ids[first] in union:
        at = int(np.flatnonzero(union[order] == ids[first])[0])
        order = np.concatenate([order[at:at + 1], order[:at], order[at + 1:]])
    return union[order], dist[order]


def distinct_first(index_distances: np.ndarray, ratio: float) -> int | None:
    """Index (into index_distances (n,)) of the nearest when it is under `ratio` times the second
    nearest (Lowe's ratio test), else None; None with fewer than two."""
    if len(index_distances) < 2 or ratio <= 0:
        return None
    two = np.argsort(index_distances, kind="stable")[:2]
    d1, d2 = index_distances[two]
    return int(two[0]) if d1 < ratio * d2 else None
