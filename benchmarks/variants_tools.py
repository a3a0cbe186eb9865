"""A held-out variant set for benchmarks/variants_detect.py (`--tools other`): copies made with tools the
detection code's thresholds never saw (variants_detect_kinds.py makes its decimations with
fast-simplification's quadric and its remeshes with gpytoolbox).

- VTK (`vtk`): vtkDecimatePro to 50 % and 10 % (moves no vertex, splits and deletes boundary vertices
  on its own rules) and vtkQuadricClustering (one vertex per grid cell, at the cell's quadric optimum);
- MeshLab (`pymeshlab`): quadric edge collapse with other options (no optimal placement: vertices stay
  at one end of the collapsed edge; planar quadrics, boundary and normals preserved), clustering
  decimation, its isotropic explicit remeshing (another remesher), Loop and Butterfly subdivision, and
  a repair (faces flipped at random, then duplicate/null faces removed, orientation made coherent);
- numpy / trimesh: midpoint subdivision, vertex-clustering decimation (cell means), a UV-seam split
  (vertices duplicated along three random planes, as an exporter does at chart borders), a renumbering
  of vertices, faces and corners, a similarity (random rotation, translation and a log-uniform scale
  in [0.05, 20]) with and without renumbering, and a mirror about a random plane, renumbered.

Every variant goes through app.core.mesh.clean, as a parsed upload does (it welds the seam split's
copies again, as load_mesh would). The tools are optional (`pip install shapebag[bench]`); a tool
that is missing or refuses a mesh leaves its kinds out, named once on stderr.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator

import numpy as np
from scipy.spatial.transform import Rotation

from app.core.mesh import Mesh, clean

MIN_VERTICES = 20  # as variants_detect_kinds: no decimation below this many vertices
_warned: set[str] = set()


def mean_edge(mesh: Mesh) -> float:
    edges = np.sort(mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    edges = np.unique(edges, axis=0)
    return float(np.linalg.norm(mesh.vertices[edges[:, 0]] - mesh.vertices[edges[:, 1]], axis=1).mean())


def diagonal(mesh: Mesh) -> float:
    return float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))


# --- VTK -------------------------------------------------------------------------------------------

def _to_vtk(mesh: Mesh):  # type: ignore[no-untyped-def]
    import vtk
    from vtk.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray

    points = vtk.vtkPoints()
    points.SetData(numpy_to_vtk(np.ascontiguousarray(mesh.vertices, np.float64), deep=True))
    cells = np.hstack([np.full((mesh.n_faces, 1), 3), mesh.faces]).astype(np.int64).ravel()
    polys = vtk.vtkCellArray()
    polys.SetCells(mesh.n_faces, numpy_to_vtkIdTypeArray(cells, deep=True))
    poly = vtk.vtkPolyData()
    poly.SetPoints(points)
    poly.SetPolys(polys)
    return poly


def _from_vtk(poly) -> Mesh:  # type: ignore[no-untyped-def]
    import vtk
    from vtk.util.numpy_support import vtk_to_numpy

    tri = vtk.vtkTriangleFilter()
    tri.SetInputData(poly)
    tri.Update()
    out = tri.GetOutput()
    vertices = vtk_to_numpy(out.GetPoints().GetData()).astype(np.float64)
    cells = vtk_to_numpy(out.GetPolys().GetConnectivityArray()).astype(np.int64)
    return Mesh(vertices, cells.reshape(-1, 3))


def vtk_decimate_pro(mesh: Mesh, fraction: float) -> Mesh:
    import vtk

    dec = vtk.vtkDecimatePro()
    dec.SetInputData(_to_vtk(mesh))
    dec.SetTargetReduction(1.0 - fraction)
    dec.Update()
    return _from_vtk(dec.GetOutput())


def vtk_quadric_clustering(mesh: Mesh) -> Mesh:
    """One vertex per cell of a grid whose cells are about twice the mean edge long."""
    import vtk

    cell = 2.0 * mean_edge(mesh)
    divisions = np.clip(np.ceil(np.ptp(mesh.vertices, axis=0) / cell), 2, 512).astype(int)
    cl = vtk.vtkQuadricClustering()
    cl.SetInputData(_to_vtk(mesh))
    cl.SetNumberOfDivisions(*(int(d) for d in divisions))
    cl.Update()
    return _from_vtk(cl.GetOutput())


# --- MeshLab ---------------------------------------------------------------------------------------

def _meshlab(mesh: Mesh, apply: Callable) -> Mesh:  # type: ignore[type-arg]
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(np.ascontiguousarray(mesh.vertices, np.float64),
                               np.ascontiguousarray(mesh.faces, np.int32)))
    apply(ms, pymeshlab)
    m = ms.current_mesh()
    return Mesh(np.asarray(m.vertex_matrix(), np.float64), np.asarray(m.face_matrix(), np.int64))


def meshlab_quadric(mesh: Mesh, fraction: float) -> Mesh:
    """Quadric edge collapse to `fraction` of the faces, options unlike fast-simplification's."""
    target = max(8, int(fraction * mesh.n_faces))
    return _meshlab(mesh, lambda ms, pm: ms.meshing_decimation_quadric_edge_collapse(
        targetfacenum=target, qualitythr=0.5, preserveboundary=True, preservenormal=True,
        optimalplacement=False, planarquadric=True))


def meshlab_clustering(mesh: Mesh) -> Mesh:
    percent = 200.0 * mean_edge(mesh) / diagonal(mesh)  # cells about twice the mean edge
    return _meshlab(mesh, lambda ms, pm: ms.meshing_decimation_clustering(
        threshold=pm.PercentageValue(percent)))


def meshlab_isotropic(mesh: Mesh) -> Mesh:
    length = 1.5 * mean_edge(mesh)
    return _meshlab(mesh, lambda ms, pm: ms.meshing_isotropic_explicit_remeshing(
        iterations=5, targetlen=pm.PureValue(length)))


def meshlab_subdivide(mesh: Mesh, scheme: str) -> Mesh:
    def apply(ms, pm):  # type: ignore[no-untyped-def]
        getattr(ms, f"meshing_surface_subdivision_{scheme}")(iterations=1, threshold=pm.PercentageValue(0.0))

    return _meshlab(mesh, apply)


def meshlab_repair(mesh: Mesh, rng: np.random.Generator) -> Mesh:
    """A third of the faces flipped, then MeshLab's repair filters (the surface is unchanged)."""
    faces = mesh.faces.copy()
    flip = rng.random(len(faces)) < 1 / 3
    faces[flip] = faces[flip][:, ::-1]

    def apply(ms, pm):  # type: ignore[no-untyped-def]
        ms.meshing_remove_duplicate_vertices()
        ms.meshing_remove_duplicate_faces()
        ms.meshing_remove_null_faces()
        ms.meshing_re_orient_faces_coherently()
        ms.meshing_remove_unreferenced_vertices()

    return _meshlab(Mesh(mesh.vertices, faces), apply)


# --- numpy / trimesh -------------------------------------------------------------------------------

def midpoint(mesh: Mesh) -> Mesh:
    import trimesh

    vertices, faces = trimesh.remesh.subdivide(mesh.vertices, mesh.faces)
    return Mesh(np.asarray(vertices, np.float64), np.asarray(faces, np.int64))


def cluster_decimate(mesh: Mesh, rng: np.random.Generator) -> Mesh:
    """Vertex clustering: each vertex moved to the mean of its grid cell (cells about twice the mean
    edge, in a random orientation), faces that collapse dropped."""
    turn = Rotation.random(random_state=rng).as_matrix()
    local = mesh.vertices @ turn.T
    cell = 2.0 * mean_edge(mesh)
    keys = np.floor((local - local.min(axis=0)) / cell + rng.random(3)).astype(np.int64)
    _, label = np.unique(keys, axis=0, return_inverse=True)
    label = label.ravel()
    n = int(label.max()) + 1
    counts = np.bincount(label, minlength=n)[:, None]
    means = np.stack([np.bincount(label, weights=mesh.vertices[:, k], minlength=n) for k in range(3)], 1)
    faces = label[mesh.faces]
    keep = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    return Mesh(means / counts, faces[keep])


def seam_split(mesh: Mesh, rng: np.random.Generator) -> Mesh:
    """Charts cut by three random planes through the centroid; each chart gets its own copies of the
    vertices it shares with another (an exporter splitting at UV seams)."""
    centres = mesh.vertices[mesh.faces].mean(axis=1) - mesh.vertices.mean(axis=0)
    normals = rng.normal(size=(3, 3))
    chart = ((centres @ normals.T) > 0) @ np.array([1, 2, 4])  # (f,) chart of each face
    key = mesh.faces * 8 + chart[:, None]  # one vertex copy per (vertex, chart)
    uniq, inverse = np.unique(key.ravel(), return_inverse=True)
    return Mesh(mesh.vertices[uniq // 8], inverse.reshape(-1, 3).astype(np.int64))


def renumbered(mesh: Mesh, rng: np.random.Generator) -> Mesh:
    """Vertices, faces and each face's corners (cyclically, keeping the winding) in a random order."""
    perm = rng.permutation(mesh.n_vertices)
    inverse = np.empty_like(perm)
    inverse[perm] = np.arange(len(perm))
    faces = inverse[mesh.faces][rng.permutation(mesh.n_faces)]
    shift = rng.integers(0, 3, len(faces))
    faces = np.take_along_axis(faces, (np.arange(3)[None] + shift[:, None]) % 3, axis=1)
    return Mesh(mesh.vertices[perm], faces)


def similarity(mesh: Mesh, rng: np.random.Generator) -> Mesh:
    """A random rotation, a shift of a few diagonals and a log-uniform scale in [0.05, 20]."""
    scale = float(np.exp(rng.uniform(np.log(0.05), np.log(20.0))))
    turn = Rotation.random(random_state=rng).as_matrix()
    shift = rng.normal(size=3) * 3.0 * diagonal(mesh)
    return Mesh(scale * mesh.vertices @ turn.T + shift, mesh.faces)


def mirrored(mesh: Mesh, rng: np.random.Generator) -> Mesh:
    """Reflected about a random plane through a random point (winding reversed, as a mirror tool does)."""
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    reflect = np.eye(3) - 2.0 * np.outer(n, n)
    return Mesh(mesh.vertices @ reflect.T + rng.normal(size=3) * diagonal(mesh), mesh.faces[:, ::-1])


# --- the set ---------------------------------------------------------------------------------------

def tool_variants(base: Mesh, rng: np.random.Generator) -> Iterator[tuple[str, Mesh, str]]:
    """(kind, variant, expected relation of the variant to the base), as variants_detect_kinds.variants.
    `mirror` kinds are expected `mirrored` (the benchmark's mirror_truth turns that into `moved` or
    `identical` for a base whose triangles are mirror-symmetric)."""
    n = base.n_vertices
    makers: list[tuple[str, Callable[[], Mesh], str]] = []
    for fraction in (0.5, 0.1):
        if fraction * n >= MIN_VERTICES:
            makers += [
                (f"vtk:decimate_pro:{fraction:.0%}", lambda f=fraction: vtk_decimate_pro(base, f),
                 "retriangulated"),
                (f"meshlab:quadric:{fraction:.0%}", lambda f=fraction: meshlab_quadric(base, f),
                 "retriangulated"),
            ]
    makers += [
        ("vtk:quadric_clustering", lambda: vtk_quadric_clustering(base), "retriangulated"),
        ("meshlab:clustering", lambda: meshlab_clustering(base), "retriangulated"),
        ("numpy:clustering", lambda: cluster_decimate(base, rng), "retriangulated"),
        ("meshlab:isotropic", lambda: meshlab_isotropic(base), "retriangulated"),
        ("meshlab:loop", lambda: meshlab_subdivide(base, "loop"), "retriangulated"),
        ("meshlab:butterfly", lambda: meshlab_subdivide(base, "butterfly"), "retriangulated"),
        ("trimesh:midpoint", lambda: midpoint(base), "retriangulated"),
        ("meshlab:repair", lambda: meshlab_repair(base, rng), "identical"),
        ("numpy:seam_split", lambda: seam_split(base, rng), "identical"),
        ("numpy:renumber", lambda: renumbered(base, rng), "identical"),
        ("numpy:similarity", lambda: similarity(base, rng), "rescaled"),
        ("numpy:similarity+renumber", lambda: renumbered(similarity(base, rng), rng), "rescaled"),
        ("numpy:mirror_plane+renumber", lambda: renumbered(mirrored(base, rng), rng), "mirrored"),
    ]
    for kind, make, expected in makers:
        try:
            made = clean(make())
        except ImportError as exc:
            _warn(kind.split(":")[0], f"not installed ({exc.name}): pip install shapebag[bench]")
            continue
        except Exception as exc:  # noqa: BLE001 - a tool that refuses this mesh (MeshLab's subdivision
            # needs a 2-manifold) or leaves no valid one: that kind is left out for this base
            print(f"variants_tools: {kind} on a mesh of {n} vertices: {str(exc).splitlines()[-1][:90]}",
                  file=sys.stderr)
            continue
        if expected == "retriangulated" and made.n_vertices < MIN_VERTICES:
            continue
        yield kind, made, expected


def _warn(what: str, why: str) -> None:
    if what not in _warned:
        _warned.add(what)
        print(f"variants_tools: {what}: {why}", file=sys.stderr)
