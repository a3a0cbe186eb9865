"""A labelled corpus of rigid, man-made classes, triangulated as CAD and 3D-print files are.

    python -m benchmarks.rigid OUT [--classes 10] [--per-class 12] [--seed 0]

Every other column is organic: SHREC'11's animals and humans, the synthetic body plans, the scan-like
shapes made from them. A held-out "mixed benchmark" has rigid classes too, and a user's
collection may be parts, furniture and tools. Here each class is a constructive solid (manifold3d
booleans of boxes, cylinders, tori, revolved profiles and extruded outlines: a watertight union, as a
CAD export is), an instance draws its own proportions (±20 % per dimension, some classes a discrete
choice: a gear's teeth, a bracket's holes) and a chord tolerance (16-48 segments around a circle),
then a random rigid motion and uniform scale. The triangulation is the solid modeller's: large flat
faces as a few long triangles, fans on discs, nothing like marching cubes' even sampling. Write OUT
outside the repository (var/ is ignored); the meshes are never committed.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

import numpy as np
from manifold3d import CrossSection, Manifold
from scipy.spatial.transform import Rotation

from app.core.mesh import Mesh, clean
from benchmarks.variants import write_labelled

SPREAD = 0.2  # each proportion is drawn in [1 - SPREAD, 1 + SPREAD] times its class's value
SEGMENTS = (16, 48)  # segments around a circle: the exporter's chord tolerance


class _Draw:
    """One instance's random choices: proportions and tessellation from one stream."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.segments = int(rng.integers(SEGMENTS[0], SEGMENTS[1] + 1))

    def __call__(self, value: float) -> float:
        return value * float(self.rng.uniform(1.0 - SPREAD, 1.0 + SPREAD))

    def cylinder(self, height: float, radius: float, top: float = -1.0) -> Manifold:
        """Along +z from z = 0."""
        return Manifold.cylinder(height, radius, top, self.segments)

    def torus(self, major: float, minor: float) -> Manifold:
        """About the z axis, centred at the origin."""
        tube = CrossSection.circle(minor, max(self.segments // 2, 8)).translate((major, 0.0))
        return Manifold.revolve(tube, self.segments)


def _box(x: float, y: float, z: float, at: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> Manifold:
    return Manifold.cube((x, y, z), True).translate(at)


def mug(d: _Draw) -> Manifold:
    r, h, wall = d(0.5), d(1.0), d(0.05)
    body = d.cylinder(h, r) - d.cylinder(h, r - wall).translate((0.0, 0.0, wall))
    major, minor = d(0.28), d(0.06)
    handle = d.torus(major, minor).rotate((90.0, 0.0, 0.0)).translate((r + major - 2 * minor, 0.0, h / 2))
    return body + (handle - d.cylinder(h, r - wall).translate((0.0, 0.0, wall)))


def table(d: _Draw) -> Manifold:
    w, dep, h, top, leg = d(2.0), d(1.2), d(1.0), d(0.08), d(0.05)
    shape = _box(w, dep, top, (0.0, 0.0, h - top / 2))
    for sx in (-1, 1):
        for sy in (-1, 1):
            # legs reach into the top: a union of solids that only touch is several pieces
            at = (sx * (w / 2 - 2 * leg), sy * (dep / 2 - 2 * leg), 0.0)
            shape += d.cylinder(h - top / 2, leg).translate(at)
    return shape


def chair(d: _Draw) -> Manifold:
    w, seat, h, back, leg = d(1.0), d(0.08), d(0.5), d(0.7), d(0.06)
    shape = _box(w, w, seat, (0.0, 0.0, h + seat / 2))
    reach = h + seat / 2  # legs end inside the seat: solids that only touch are several pieces
    for sx in (-1, 1):
        for sy in (-1, 1):
            shape += _box(leg, leg, reach, (sx * (w - leg) / 2, sy * (w - leg) / 2, reach / 2))
    rest = back + seat / 2  # the back starts inside the seat
    return shape + _box(w, leg, rest, (0.0, (w - leg) / 2, h + seat / 2 + rest / 2))


def bottle(d: _Draw) -> Manifold:
    r, body, shoulder, neck_r, neck = d(0.4), d(1.0), d(0.3), d(0.12), d(0.35)
    profile = [(0.0, 0.0), (r, 0.0), (r, body), (neck_r, body + shoulder), (neck_r, body + shoulder + neck),
               (0.0, body + shoulder + neck)]
    return Manifold.revolve(CrossSection([profile]), d.segments)


def lamp(d: _Draw) -> Manifold:
    base_r, base_h, pole_r, pole_h = d(0.4), d(0.06), d(0.03), d(1.2)
    shade_lo, shade_hi, shade_h, wall = d(0.45), d(0.2), d(0.4), d(0.03)
    # the inner cone stops a wall short of the top: a closed crown the pole runs into
    inner = d.cylinder(shade_h, shade_lo - wall, shade_hi - wall).translate((0.0, 0.0, -wall))
    shade = d.cylinder(shade_h, shade_lo, shade_hi) - inner
    shade = shade.translate((0.0, 0.0, pole_h - shade_h + wall / 2))
    return d.cylinder(base_h, base_r) + d.cylinder(pole_h, pole_r) + shade


def airplane(d: _Draw) -> Manifold:
    length, r, span, chord = d(2.0), d(0.12), d(2.0), d(0.4)
    fuselage = d.cylinder(length, r).rotate((0.0, 90.0, 0.0)).translate((-length / 2, 0.0, 0.0))
    nose = Manifold.sphere(r, d.segments).translate((length / 2, 0.0, 0.0))
    wings = _box(chord, span, d(0.04))
    tail_x = -length / 2 + d(0.12)
    tailplane = _box(d(0.2), d(0.7), d(0.03), (tail_x, 0.0, 0.0))
    fin_h = d(0.35)
    fin = _box(d(0.25), d(0.03), fin_h, (tail_x, 0.0, fin_h / 2))
    return fuselage + nose + wings + tailplane + fin


def dumbbell(d: _Draw) -> Manifold:
    bar_r, bar, plate_r, plate = d(0.05), d(1.2), d(0.3), d(0.1)
    shape = d.cylinder(bar, bar_r).translate((0.0, 0.0, -bar / 2))
    plates = int(d.rng.integers(1, 3))  # one or two plates a side
    for side in (-1, 1):
        for k in range(plates):
            z = side * (bar / 2 - d(0.1) - k * plate * 1.1)
            shape += d.cylinder(plate, plate_r * (1.0 - 0.15 * k)).translate((0.0, 0.0, z - plate / 2))
    return shape


def bracket(d: _Draw) -> Manifold:
    a, b, t, width, hole = d(1.0), d(0.8), d(0.12), d(0.8), d(0.08)
    outline = CrossSection([[(0.0, 0.0), (a, 0.0), (a, t), (t, t), (t, b), (0.0, b)]])
    shape = Manifold.extrude(outline, width)
    holes = int(d.rng.integers(1, 3))  # per flange
    for k in range(holes):
        z = width * (k + 1) / (holes + 1)
        drill = d.cylinder(4 * t, hole).translate((0.0, 0.0, -2 * t))
        shape -= drill.rotate((90.0, 0.0, 0.0)).translate((0.6 * a, 0.0, z)).translate((0.0, 2 * t, 0.0))
        shape -= drill.rotate((0.0, 90.0, 0.0)).translate((0.0, 0.6 * b, z)).translate((2 * t, 0.0, 0.0))
    return shape


def gear(d: _Draw) -> Manifold:
    teeth, r, depth, thick, bore = int(d.rng.integers(10, 17)), 1.0, d(0.15), d(0.25), d(0.2)
    angles = np.linspace(0.0, 2 * np.pi, 4 * teeth, endpoint=False)
    radii = np.tile([r, r, r - depth, r - depth], teeth)
    outline = CrossSection([[(float(q * np.cos(t)), float(q * np.sin(t))) for q, t in zip(radii, angles,
                                                                                          strict=True)]])
    return Manifold.extrude(outline, thick) - d.cylinder(thick * 3, bore).translate((0.0, 0.0, -thick))


def hammer(d: _Draw) -> Manifold:
    handle_r, handle, head, head_w = d(0.05), d(1.2), d(0.5), d(0.12)
    return d.cylinder(handle, handle_r) + _box(head, head_w, head_w * 1.2, (0.0, 0.0, handle))


CLASSES: dict[str, Callable[[_Draw], Manifold]] = {
    f.__name__: f for f in (mug, table, chair, bottle, lamp, airplane, dumbbell, bracket, gear, hammer)
}


def rigid_shape(name: str, rng: np.random.Generator) -> Mesh:
    """One instance of a class: the solid's own triangulation after a random rigid motion and scale."""
    solid = CLASSES[name](_Draw(rng))
    out = solid.to_mesh()
    v = np.asarray(out.vert_properties, dtype=np.float64)[:, :3]
    f = np.asarray(out.tri_verts, dtype=np.int64)
    rotation = Rotation.random(random_state=rng).as_matrix()
    v = (v - v.mean(axis=0)) @ rotation.T * rng.uniform(0.5, 2.0) + rng.uniform(-1.0, 1.0, size=3)
    return clean(Mesh(v, f))


def generate(out: Path | str, classes: int = len(CLASSES), per_class: int = 12, seed: int = 0) -> Path:
    """Write classes x per_class OBJ meshes and labels.csv (file,class) under `out`; return it.
    Each shape has its own stream (seed, class, index, 11): the same arguments give the same files."""
    if not 1 <= classes <= len(CLASSES):
        raise ValueError(f"classes must be between 1 and {len(CLASSES)}")
    return write_labelled(Path(out), list(CLASSES)[:classes], per_class,
                          lambda c, name, i: rigid_shape(name, np.random.default_rng([seed, c, i, 11])))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("out")
    p.add_argument("--classes", type=int, default=len(CLASSES))
    p.add_argument("--per-class", type=int, default=12)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    print("wrote", generate(a.out, a.classes, a.per_class, a.seed) / "labels.csv")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
