"""Issue 34's hostile files through the reader, timed: each file's size, what it gets and how fast.

    python -m benchmarks.hostile_files                      # the structure bombs, at the test limit
    python -m benchmarks.hostile_files --max-vertices 2000000   # at the service's default limit

Every structure bomb is refused from its declarations (the reader counts the expansion on the graph), so
the time is that of parsing a few kilobytes; before, the 3MF chain expanded for ~60 s and the COLLADA
DAG to 3.5 GiB. Also reads scenes just under the placement limit, which are built for real.
"""

from __future__ import annotations

import argparse
import time

from app.core.mesh import InvalidMeshError, load_mesh
from tests.reliability import hostile as h
from tests.reliability.test_structure_counts import BOMBS


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-vertices", type=int, default=3000)
    args = parser.parse_args()
    near_limit = [
        ("3mf-6561-placements", "near.3mf", h.component_chain_3mf(9, 3)),
        ("dae-1900-placements", "near.dae", h.instance_node_dae(2, 1900)),
        ("gltf-49k-nodes", "near.zip", h.many_nodes_zip(49_000)),
    ]
    cases = [(c, f, data) for c, f, data, _ in BOMBS] + near_limit
    print(f"{'case':28s} {'bytes':>7s} {'ms':>8s}  answer")
    for case, filename, data in cases:
        t = time.perf_counter()
        try:
            mesh = load_mesh(data, filename, max_vertices=args.max_vertices)
            answer = f"read: {mesh.n_vertices} vertices, {mesh.n_faces} faces"
        except InvalidMeshError as exc:
            answer = f"422: {str(exc)[:90]}"
        print(f"{case:28s} {len(data):7d} {1000 * (time.perf_counter() - t):8.1f}  {answer}")


if __name__ == "__main__":
    main()
