"""Counting a scene graph before expanding it: glTF nodes, COLLADA instance_node, 3MF components.

A scene stores each part once and places it many times, and places groups of places: a DAG whose
expansion grows with the product of the copies along each path (a 3 KB 3MF chain of 20 levels, each
placing 3 copies of the last, means 3^20 parts). The totals are computed on the DAG, memoised per node,
so counting costs the size of the file, not of its expansion; cycles and deep chains are refused.
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass
from typing import TypeVar

from app.core.meshdata import Budget, InvalidMeshError

MAX_PLACEMENTS = 10_000  # meshes placed in the flattened scene (each a copy, its transform applied)
MAX_DEPTH = 64  # levels of nesting (nodes in nodes, components of components)
MAX_NODES = 50_000  # nodes, objects or primitives a scene may declare at all
K = TypeVar("K", bound=Hashable)


@dataclass(frozen=True)
class Totals:
    """What a node expands to: meshes placed, vertices and faces over all placements."""

    placements: int = 0
    vertices: int = 0
    faces: int = 0

    def __add__(self, other: Totals) -> Totals:
        return Totals(
            self.placements + other.placements, self.vertices + other.vertices, self.faces + other.faces
        )


def expand(
    roots: Sequence[K],
    children: Mapping[K, Sequence[K]],
    own: Mapping[K, Totals],
    what: str,
) -> Totals:
    """Totals of placing every root once: own content of each node plus its children, recursively.

    children: node -> the nodes it places (a node placed twice is listed twice); own: node -> what the
    node itself holds. A node missing from both is empty. Raises InvalidMeshError on a cycle or on
    nesting deeper than MAX_DEPTH.
    """
    done: dict[K, Totals] = {}
    for root in roots:
        if root in done:
            continue
        # iterative depth-first walk: (node, index of the next child); `path` holds the open nodes
        stack: list[tuple[K, int]] = [(root, 0)]
        open_nodes = {root}
        while stack:
            node, at = stack[-1]
            kids = children.get(node, ())
            if at < len(kids):
                stack[-1] = (node, at + 1)
                kid = kids[at]
                if kid in done:
                    continue
                if kid in open_nodes:
                    raise InvalidMeshError(f"the {what} refers to itself in a cycle: the file is corrupt")
                if len(stack) >= MAX_DEPTH:
                    raise InvalidMeshError(f"the {what} nests more than {MAX_DEPTH} levels deep")
                stack.append((kid, 0))
                open_nodes.add(kid)
                continue
            total = own.get(node, Totals())
            for kid in kids:
                total = total + done[kid]
            done[node] = total
            open_nodes.discard(node)
            stack.pop()
    total = Totals()
    for root in roots:
        total = total + done[root]
    return total


def check(total: Totals, what: str, budget: Budget, max_placements: int = MAX_PLACEMENTS) -> None:
    """Refuse a scene whose expansion places too many meshes or too many vertices or faces."""
    where = f"the {what} (each part counted once per placement)"
    if total.placements > max_placements:
        raise InvalidMeshError(
            f"{where} places {total.placements} meshes, more than the limit of {max_placements}:"
            " merge the instances into one mesh and export again"
        )
    budget.vertices(total.vertices, where)
    budget.faces(total.faces, where)


def check_declared(count: int, kind: str, what: str) -> None:
    if count > MAX_NODES:
        raise InvalidMeshError(f"the {what} declares {count} {kind}, more than the limit of {MAX_NODES}")
