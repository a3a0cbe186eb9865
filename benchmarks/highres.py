"""Two labelled columns that look like users' collections at full resolution (issue 30).

    python -m benchmarks.highres OUT --kind fine        [--per-class 10] [--seed 0] [--holes 0,2]
    python -m benchmarks.highres OUT --kind characters  [--per-class 10] [--seed 0]
    python -m benchmarks.highres OUT --kind kin-characters  [--per-class 10] [--seed 0]

**fine**: full-resolution scans of kin shapes. Nine classes share two body plans (six quadrupeds, three
bipeds) and differ only by small parts: ears up or down, a snout, horns, a hump, a bushy tail; a nose,
a hair bun, a belly. Within a class, shapes differ by pose only (one subject scanned in several
poses; limbs keep their length and thickness). The small parts are 2-4 edges of a 1,000-vertex mesh across:
what tells a cat from a dog at the canonical resolution. Each surface is extracted by marching cubes
on a fine grid, decimated to 15k-50k vertices (log-uniform), cut by 0-2 holes (the largest piece
kept), moved and rescaled at random.

**characters**: posed characters sharing one template per class. Five body plans (quadruped, bird,
dinosaur, hand, octopus); each class's template is extracted once in the rest pose at 5k-40k vertices,
and every member is that template posed by linear blend skinning on the plan's skeleton: the same
vertices and faces, other joint angles, the skinning's own creases at bent joints.

Noise is added by `shapebag evaluate --noise NSR`, to the input mesh: at full resolution, where a
scanner puts it. Write OUT outside the repository (var/ is ignored); the meshes are never committed.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from app.core.mesh import Mesh, clean
from app.datasets.bodyplans import PLANS, Chain
from app.datasets.synthetic import Frame, Segment, capsule_distance, pose_frames, random_motion, surface
from benchmarks.scans import _decimate, _with_holes
from benchmarks.variants import write_labelled

GRID = 220  # marching-cubes voxels along the longest side: ~40k-90k vertices before decimation
FINE_VERTICES = (15_000, 50_000)
CHARACTER_VERTICES = (5_000, 40_000)
CHARACTER_PLANS = ("quadruped", "bird", "dinosaur", "hand", "octopus")
SKIN_SOFTNESS = 0.04  # body units: how far a vertex's skinning weights blend across a joint


@dataclass(frozen=True)
class Part:
    """A small capsule fixed to one segment of a plan, in rest-pose body coordinates.

    chain, segment : which segment carries it (it follows that segment's pose)
    at             : rest position of its root; direction: rest direction; length; radii (root, tip)
    """

    chain: int
    segment: int
    at: tuple[float, float, float]
    direction: tuple[float, float, float]
    length: float
    radii: tuple[float, float]


def _pair(chain: int, segment: int, at: tuple[float, float, float], direction: tuple[float, float, float],
          length: float, radii: tuple[float, float]) -> list[Part]:
    """The part and its mirror image across the plane z = 0 (ears, horns)."""
    mirror = (at[0], at[1], -at[2]), (direction[0], direction[1], -direction[2])
    return [Part(chain, segment, at, direction, length, radii),
            Part(chain, segment, mirror[0], mirror[1], length, radii)]


# quadruped: chain 5 is the neck (segment 1 the head, from (1.28, 0.56) to (1.73, 0.47)), 0 the body,
# 6 the tail; biped: chain 0 the torso, 1 the head (centre (0, 1.4))
EARS_UP = _pair(5, 1, (1.36, 0.66, 0.08), (-0.2, 1.0, 0.35), 0.3, (0.08, 0.05))
EARS_DOWN = _pair(5, 1, (1.36, 0.64, 0.1), (-0.3, -0.5, 1.0), 0.28, (0.07, 0.05))
SNOUT = [Part(5, 1, (1.7, 0.47, 0.0), (1.0, -0.15, 0.0), 0.25, (0.09, 0.07))]
HORNS = _pair(5, 1, (1.42, 0.66, 0.06), (-0.6, 1.0, 0.25), 0.33, (0.07, 0.05))
HUMP = [Part(0, 0, (-0.1, 0.3, 0.0), (0.0, 1.0, 0.0), 0.16, (0.2, 0.12))]
TUFT = [Part(6, 1, (-1.75, 0.35, 0.0), (-1.0, 0.3, 0.0), 0.2, (0.13, 0.1))]
NOSE = [Part(1, 0, (0.0, 1.42, 0.17), (0.0, -0.3, 1.0), 0.12, (0.06, 0.04))]
BUN = [Part(1, 0, (0.0, 1.5, -0.15), (0.0, 0.5, -1.0), 0.12, (0.12, 0.1))]
BELLY = [Part(0, 0, (0.0, 0.3, 0.2), (0.0, 0.0, 1.0), 0.1, (0.2, 0.15))]
PERSON_EARS = _pair(1, 0, (0.0, 1.43, 0.17), (0.0, 0.0, 1.0), 0.06, (0.07, 0.06))

KIN: dict[str, tuple[str, list[Part]]] = {
    "cat": ("quadruped", EARS_UP),
    "dog": ("quadruped", EARS_DOWN + SNOUT),
    "wolf": ("quadruped", EARS_UP + SNOUT + TUFT),
    "goat": ("quadruped", HORNS),
    "camel": ("quadruped", HUMP + SNOUT),
    "bull": ("quadruped", HORNS + HUMP + TUFT),
    "person_a": ("biped", NOSE + PERSON_EARS),
    "person_b": ("biped", NOSE + BUN),
    "person_c": ("biped", BELLY + PERSON_EARS),
}


def posed_parts(parts: list[Part], segments: list[Segment], frames: list[Frame], chain_starts: list[int],
                anchors: list[np.ndarray], rng: np.random.Generator) -> list[Segment]:
    """Each part as a capsule carried by its segment's rigid frame, its size jittered by +-10 %.
    anchors: each segment's start in the rest pose of the plan as PLANS defines it (parts are placed
    there, whatever the class's proportions)."""
    out: list[Segment] = []
    for part in parts:
        s = chain_starts[part.chain] + part.segment
        rot = frames[s][1]
        size = rng.uniform(0.9, 1.1)
        direction = np.asarray(part.direction, dtype=float)
        direction /= np.linalg.norm(direction)
        root = np.asarray(segments[s][0]) + rot @ (np.asarray(part.at, dtype=float) - anchors[s])
        out.append((root, root + rot @ direction * part.length * size,
                    part.radii[0] * size, part.radii[1] * size))
    return out


# Each kin class's own proportions, as (chain, segment or None for the whole chain) -> (length scale,
# radius scale): kin differ in build as well as in small parts (a camel's legs and neck, a bull's
# bulk, a slim and a broad person). Quadruped chains: 0 body, 1-4 legs, 5 neck (segment 1 the head,
# never scaled: parts sit on it), 6 tail; biped: 0 torso, 1 head, 2 neck, 3-4 arms, 5-6 legs.
# A chain that carries a part keeps its radius.
_LEGS4 = (1, 2, 3, 4)
PROPORTIONS: dict[str, dict[tuple[int, int | None], tuple[float, float]]] = {
    "cat": {**{(c, None): (0.85, 0.85) for c in _LEGS4}, (5, 0): (0.8, 1.0), (6, None): (1.3, 0.85)},
    "dog": {},
    "wolf": {**{(c, None): (1.1, 1.0) for c in _LEGS4}, (0, None): (1.1, 1.1), (6, None): (1.1, 1.0)},
    "goat": {**{(c, None): (0.9, 0.9) for c in _LEGS4}, (5, 0): (1.15, 0.9), (0, None): (0.9, 1.0)},
    "camel": {**{(c, None): (1.3, 0.9) for c in _LEGS4}, (5, 0): (1.45, 0.9)},
    "bull": {**{(c, None): (0.85, 1.3) for c in _LEGS4}, (5, 0): (0.75, 1.3)},
    "person_a": {},
    "person_b": {**{(c, None): (1.08, 0.82) for c in (3, 4, 5, 6)}, (0, None): (1.0, 0.88)},
    "person_c": {**{(c, None): (0.95, 1.2) for c in (3, 4, 5, 6)}, (2, None): (0.8, 1.2)},
}


def kin_chains(name: str) -> tuple[list[Chain], list[np.ndarray]]:
    """The kin class's chains (its plan in its own proportions) and the plan's rest segment starts."""
    plan = KIN[name][0] if name in KIN else name
    base = PLANS[plan]()
    scales = PROPORTIONS.get(name, {})
    chains = []
    for c, chain in enumerate(base):
        lengths, radii = list(chain.lengths), list(chain.radii)
        for s in range(len(lengths)):
            ls, rs = scales.get((c, s), scales.get((c, None), (1.0, 1.0)))
            lengths[s], radii[s] = lengths[s] * ls, (radii[s][0] * rs, radii[s][1] * rs)
        chains.append(replace(chain, lengths=tuple(lengths), radii=tuple(radii)))
    return chains, [np.asarray(seg[0], dtype=float) for seg in _rest_segments(base)]


def fine_shape(name: str, rng: np.random.Generator, holes: tuple[int, int] = (0, 2),
               grid: int = GRID, vertex_range: tuple[int, int] = FINE_VERTICES) -> Mesh:
    """One member of a kin class: posed plan plus its small parts, at full resolution."""
    parts = KIN[name][1]
    chains, anchors = kin_chains(name)
    segments, frames = pose_frames(chains, rng, jitter=False)  # one body per class, as a scanned subject
    starts = list(np.cumsum([0] + [len(c.lengths) for c in chains])[:-1])
    segments = segments + posed_parts(parts, segments, frames, starts, anchors, rng)
    v, f = surface(segments, grid=grid, max_vertices=None)
    mesh = Mesh(random_motion(v, rng), f)
    if holes[1] > 0:
        mesh = _with_holes(mesh, rng, holes)
    return _decimate(mesh, _log_uniform(rng, vertex_range))


def _log_uniform(rng: np.random.Generator, lo_hi: tuple[int, int]) -> int:
    return int(np.exp(rng.uniform(*np.log(lo_hi))))


def skin(template: np.ndarray, rest: list[Segment], frames: list[Frame], posed: list[Segment],
         softness: float = SKIN_SOFTNESS) -> np.ndarray:
    """Linear blend skinning: template (n, 3) in the rest pose -> (n, 3) posed.

    Each vertex blends the rigid motions of the segments whose capsules it lies nearest, with weights
    softmax(-d / softness) over its distance d to each capsule's surface.
    """
    dists = np.stack([capsule_distance(template, a, b, r0, r1) for a, b, r0, r1 in rest], axis=1)
    logits = -(dists - dists.min(axis=1, keepdims=True)) / softness  # (n, s)
    weights = np.exp(logits)
    weights /= weights.sum(axis=1, keepdims=True)
    out = np.zeros_like(template)
    for s, ((rest_start, rot), seg) in enumerate(zip(frames, posed, strict=True)):
        out += weights[:, s:s + 1] * (np.asarray(seg[0]) + (template - rest_start) @ rot.T)
    return out


def character_template(
    name: str, rng: np.random.Generator, grid: int = GRID, vertex_range: tuple[int, int] = CHARACTER_VERTICES
) -> tuple[Mesh, list[Segment], list[int]]:
    """The rest pose of a character at a random resolution: a plan's name (CHARACTER_PLANS) or a kin
    class's (KIN, with its small parts). Returns the mesh, its rest capsules and, for each capsule,
    the plan segment whose motion it follows (itself, or the segment a part is fixed to)."""
    parts = KIN[name][1] if name in KIN else []
    chains, anchors = kin_chains(name)
    rest = _rest_segments(chains)
    starts = list(np.cumsum([0] + [len(c.lengths) for c in chains])[:-1])
    frames = [(np.asarray(seg[0], dtype=float), np.eye(3)) for seg in rest]
    carriers = list(range(len(rest))) + [starts[p.chain] + p.segment for p in parts]
    rest = rest + posed_parts(parts, rest, frames, starts, anchors, np.random.default_rng(0))
    v, f = surface(rest, grid=grid, max_vertices=None)
    return _decimate(clean(Mesh(v, f)), _log_uniform(rng, vertex_range)), rest, carriers


def _rest_segments(chains: list) -> list[Segment]:
    out: list[Segment] = []
    for chain in chains:
        p = np.asarray(chain.anchor, dtype=float)
        for d, length, (r0, r1) in zip(chain.dirs, chain.lengths, chain.radii, strict=True):
            direction = np.asarray(d, dtype=float) / np.linalg.norm(d)
            out.append((p, p + direction * length, r0, r1))
            p = p + direction * length
    return out


def generate(out: Path | str, kind: str = "fine", per_class: int = 10, seed: int = 0,
             holes: tuple[int, int] = (0, 2), grid: int = GRID,
             vertex_range: tuple[int, int] | None = None) -> Path:
    """Write the column's OBJ meshes and labels.csv under `out`; return it. vertex_range: the
    resolutions drawn from (default FINE_VERTICES or CHARACTER_VERTICES)."""
    if kind == "fine":
        fine_range = vertex_range or FINE_VERTICES

        def make(c: int, name: str, i: int) -> Mesh:
            return fine_shape(name, np.random.default_rng([seed, c, i, 30]), holes=holes, grid=grid,
                              vertex_range=fine_range)

        return write_labelled(Path(out), list(KIN), per_class, make)
    if kind not in ("characters", "kin-characters"):
        raise ValueError(f"kind must be fine, characters or kin-characters, not {kind!r}")
    names = list(KIN) if kind == "kin-characters" else list(CHARACTER_PLANS)
    templates = {}
    for c, name in enumerate(names):
        templates[name] = character_template(name, np.random.default_rng([seed, c, 31]), grid=grid,
                                             vertex_range=vertex_range or CHARACTER_VERTICES)

    def pose_character(c: int, name: str, i: int) -> Mesh:
        rng = np.random.default_rng([seed, c, i, 32])
        template, rest, carriers = templates[name]
        segments, frames = pose_frames(kin_chains(name)[0], rng, jitter=False)
        moved = [segments[k] for k in carriers]  # a part moves with the segment that carries it
        posed = Mesh(skin(template.vertices, rest, [frames[k] for k in carriers], moved), template.faces)
        return Mesh(random_motion(posed.vertices, rng), posed.faces)

    return write_labelled(Path(out), names, per_class, pose_character)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("out")
    p.add_argument("--kind", choices=("fine", "characters", "kin-characters"), default="fine")
    p.add_argument("--per-class", type=int, default=10)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--holes", default="0,2", help="MIN,MAX discs cut out per shape (fine)")
    p.add_argument("--grid", type=int, default=GRID, help="marching-cubes voxels along the longest side")
    a = p.parse_args(argv)
    lo, hi = (int(x) for x in a.holes.split(","))
    out = generate(a.out, a.kind, a.per_class, a.seed, (lo, hi), a.grid)
    print("wrote", out / "labels.csv")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
