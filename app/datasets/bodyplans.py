"""Body plans of the synthetic corpus: skeletons of tapered capsules, one class each.

A plan is a list of chains. A chain starts at an anchor point (rest pose, body coordinates, y up) and is
a sequence of segments; each joint between consecutive segments (and the anchor joint) may bend. Classes
differ in their number of limbs and their proportions, i.e. in intrinsic shape, not only in pose.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Chain:
    """A limb, tail, neck or spine.

    anchor : (3,) rest position of the first joint
    dirs   : rest direction of each segment (not necessarily unit)
    lengths: length of each segment
    radii  : (r_start, r_end) of each segment: tapered capsules
    bend   : max bend in degrees at each joint (the first is the anchor joint)
    hinge  : rest-pose bend axis, carried along by the chain's rotation; None: a random axis
             perpendicular to the segment (a ball joint)
    """

    anchor: tuple[float, float, float]
    dirs: tuple[tuple[float, float, float], ...]
    lengths: tuple[float, ...]
    radii: tuple[tuple[float, float], ...]
    bend: tuple[float, ...]
    hinge: tuple[float, float, float] | None = None


Vec = tuple[float, float, float]


def _limb(
    anchor: Vec,
    direction: Vec,
    lengths: tuple[float, ...],
    radii: tuple[tuple[float, float], ...],
    bend: tuple[float, ...],
    hinge: Vec | None = None,
) -> Chain:
    """A chain whose segments all start in the same rest direction."""
    return Chain(anchor, (direction,) * len(lengths), lengths, radii, bend, hinge)


def quadruped() -> list[Chain]:
    body = _limb((-0.9, 0.0, 0.0), (1, 0, 0), (1.8,), ((0.34, 0.36),), (0,))
    legs = [
        _limb((x, -0.1, z), (0, -1, 0), (0.6, 0.6), ((0.14, 0.12), (0.12, 0.09)), (25, 40), hinge=(0, 0, 1))
        for x in (-0.75, 0.75) for z in (-0.22, 0.22)
    ]
    neck = Chain((0.9, 0.1, 0.0), ((1, 1.2, 0), (1, -0.2, 0)), (0.6, 0.45), ((0.16, 0.13), (0.17, 0.1)),
                 (25, 30))
    tail = _limb((-0.95, 0.1, 0.0), (-1, 0.3, 0), (0.45, 0.45), ((0.09, 0.08), (0.08, 0.06)), (35, 40))
    return [body, *legs, neck, tail]


def biped() -> list[Chain]:
    torso = _limb((0.0, 0.0, 0.0), (0, 1, 0), (1.1,), ((0.3, 0.27),), (0,))
    head = _limb((0.0, 1.25, 0.0), (0, 1, 0), (0.3,), ((0.19, 0.19),), (0,))
    neck = _limb((0.0, 1.0, 0.0), (0, 1, 0), (0.25,), ((0.1, 0.1),), (15,))
    arms = [
        _limb((s * 0.3, 1.0, 0.0), (s, -0.4, 0), (0.55, 0.5), ((0.1, 0.09), (0.09, 0.07)), (40, 55))
        for s in (-1, 1)
    ]
    legs = [
        _limb((s * 0.16, -0.05, 0.0), (0, -1, 0), (0.75, 0.7), ((0.13, 0.1), (0.1, 0.07)), (25, 45),
              hinge=(1, 0, 0))
        for s in (-1, 1)
    ]
    return [torso, head, neck, *arms, *legs]


def bird() -> list[Chain]:
    body = _limb((-0.55, 0.0, 0.0), (1, 0.1, 0), (1.1,), ((0.3, 0.26),), (0,))
    neck = Chain((0.55, 0.1, 0.0), ((1, 1.5, 0), (1, 0, 0)), (0.35, 0.3), ((0.12, 0.12), (0.15, 0.07)),
                 (25, 20))
    wings = [
        _limb((0.05, 0.15, s * 0.2), (0, 0.15, s), (0.8, 0.9), ((0.11, 0.1), (0.1, 0.06)), (30, 35),
              hinge=(1, 0, 0))
        for s in (-1, 1)
    ]
    legs = [
        _limb((0.0, -0.2, s * 0.12), (0, -1, 0), (0.3, 0.3), ((0.07, 0.07), (0.07, 0.06)), (20, 30),
              hinge=(0, 0, 1))
        for s in (-1, 1)
    ]
    tail = _limb((-0.55, 0.0, 0.0), (-1, 0.1, 0), (0.45,), ((0.16, 0.07),), (25,))
    return [body, neck, *wings, *legs, tail]


def snake() -> list[Chain]:
    n = 9  # body segments, then the head: one chain, so the head follows the bends
    radii = tuple((0.17 - 0.01 * i, 0.17 - 0.01 * (i + 1)) for i in range(n)) + ((0.2, 0.14),)
    spine = Chain((-2.0, 0.0, 0.0), ((1, 0, 0),) * (n + 1), (0.45,) * n + (0.3,), radii,
                  (0,) + (28,) * (n - 1) + (15,))
    return [spine]


def octopus() -> list[Chain]:
    body = _limb((0.0, 0.05, 0.0), (0, 1, 0), (0.5,), ((0.42, 0.3),), (0,))
    legs = []
    for i in range(8):
        a = 2 * np.pi * (i + 0.5) / 8
        d = (np.cos(a), -0.35, np.sin(a))
        legs.append(_limb((0.3 * np.cos(a), 0.0, 0.3 * np.sin(a)), d, (0.55, 0.5, 0.45),
                          ((0.12, 0.1), (0.1, 0.08), (0.08, 0.06)), (20, 35, 40),
                          hinge=(-np.sin(a), 0.0, np.cos(a))))
    return [body, *legs]


def hand() -> list[Chain]:
    palm = [_limb((x, 0.0, 0.0), (0, 1, 0), (0.9,), ((0.16, 0.16),), (0,))
            for x in (-0.27, -0.09, 0.09, 0.27)]
    fingers = [
        _limb((x, 0.95, 0.0), (0, 1, 0), (ln, ln * 0.75, ln * 0.6), ((0.1, 0.09), (0.09, 0.08), (0.08, 0.06)),
              (30, 35, 30), hinge=(1, 0, 0))
        for x, ln in ((-0.33, 0.38), (-0.11, 0.5), (0.11, 0.55), (0.33, 0.5))
    ]
    thumb = _limb((0.38, 0.2, 0.0), (1, 0.8, 0), (0.4, 0.35), ((0.12, 0.1), (0.1, 0.07)), (30, 35))
    return [*palm, *fingers, thumb]


def ant() -> list[Chain]:
    body = Chain((-1.1, 0.0, 0.0), ((1, 0, 0), (1, 0, 0), (1, 0, 0)), (0.7, 0.5, 0.3),
                 ((0.3, 0.3), (0.16, 0.16), (0.2, 0.2)), (0, 12, 12))
    legs = [
        _limb((x, 0.0, s * 0.1), (0, 0.5, s), (0.5, 0.7), ((0.08, 0.07), (0.07, 0.06)), (20, 30),
              hinge=(1, 0, 0))
        for x in (-0.1, 0.05, 0.2) for s in (-1, 1)
    ]
    antennae = [_limb((0.45, 0.1, s * 0.08), (1, 1, s * 0.6), (0.5,), ((0.06, 0.06),), (25,))
                for s in (-1, 1)]
    return [body, *legs, *antennae]


def dinosaur() -> list[Chain]:
    body = _limb((-0.5, 0.0, 0.0), (1, 0.35, 0), (1.1,), ((0.36, 0.3),), (0,))
    neck = Chain((0.5, 0.4, 0.0), ((1, 0.6, 0), (1, 0, 0)), (0.35, 0.45), ((0.17, 0.15), (0.2, 0.1)),
                 (20, 25))
    tail = Chain((-0.5, 0.0, 0.0), ((-1, -0.2, 0),) * 3, (0.6, 0.6, 0.5), ((0.28, 0.2), (0.2, 0.12),
                 (0.12, 0.06)), (15, 25, 30))
    legs = [
        _limb((-0.2, -0.1, s * 0.22), (0, -1, 0), (0.6, 0.55), ((0.17, 0.12), (0.12, 0.09)), (25, 40),
              hinge=(0, 0, 1))
        for s in (-1, 1)
    ]
    arms = [_limb((0.45, 0.2, s * 0.22), (0.5, -1, 0), (0.22, 0.2), ((0.07, 0.07), (0.07, 0.06)), (35, 40))
            for s in (-1, 1)]
    return [body, neck, tail, *legs, *arms]


PLANS = {
    "quadruped": quadruped,
    "biped": biped,
    "bird": bird,
    "snake": snake,
    "octopus": octopus,
    "hand": hand,
    "ant": ant,
    "dinosaur": dinosaur,
}
