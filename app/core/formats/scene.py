"""trimesh results (a Trimesh or a Scene of them) -> raw arrays, with transforms baked."""

from __future__ import annotations

import io

import numpy as np
import trimesh

from app.core.meshdata import Budget, InvalidMeshError


def load_with_trimesh(
    data: bytes, file_type: str, what: str, budget: Budget
) -> tuple[np.ndarray, np.ndarray]:
    """Parse with trimesh (no processing) and flatten: every triangle mesh of the scene, node transforms
    applied, in one (vertices (n, 3) float64, faces (f, 3) int64) pair."""
    try:
        loaded = trimesh.load(io.BytesIO(data), file_type=file_type, process=False)
        return scene_arrays(loaded, what, budget)
    except InvalidMeshError:
        raise
    except Exception as exc:  # trimesh and its helpers raise many types for corrupt files
        raise InvalidMeshError(f"could not read the file as {what}: {short(exc)}") from exc


def scene_arrays(loaded: object, what: str, budget: Budget) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(loaded, trimesh.Scene):
        _check_instances(loaded, what, budget)
        return _flatten(loaded, what)
    if isinstance(loaded, trimesh.PointCloud):
        raise InvalidMeshError("the mesh has no faces (a point cloud is not a surface)")
    if not isinstance(loaded, trimesh.Trimesh):
        raise InvalidMeshError(f"the {what} file holds no triangle mesh")
    return np.asarray(loaded.vertices, dtype=np.float64), np.asarray(loaded.faces, dtype=np.int64)


def _flatten(scene: trimesh.Scene, what: str) -> tuple[np.ndarray, np.ndarray]:
    """Every triangle mesh at every node that places it, its transform applied, as one pair of arrays.

    What Scene.dump() + concatenate give, without a Trimesh copy per placement (2,187 placements of a
    tetrahedron: 5 s of copying and re-processing, for 35 kB of arrays)."""
    vertices, faces, offset = [], [], 0
    for node in scene.graph.nodes_geometry:
        transform, name = scene.graph[node]
        geometry = scene.geometry.get(name)
        if not isinstance(geometry, trimesh.Trimesh) or not len(geometry.faces):
            continue
        v = np.asarray(geometry.vertices, dtype=np.float64)
        vertices.append(v @ transform[:3, :3].T + transform[:3, 3])
        faces.append(np.asarray(geometry.faces, dtype=np.int64) + offset)
        offset += len(v)
    if not faces:
        raise InvalidMeshError(f"the {what} file holds no triangle mesh (only points, lines or nothing)")
    return np.concatenate(vertices), np.concatenate(faces)


def short(exc: Exception) -> str:
    """One line of an exception for a user: its first line, at most 200 characters."""
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return text[:200]


def _check_instances(scene: trimesh.Scene, what: str, budget: Budget) -> None:
    """A scene stores each geometry once and places it at many nodes: count the placed copies before
    dump() allocates them (a small 3MF or COLLADA file can place one part a million times)."""
    vertices = faces = 0
    for node in scene.graph.nodes_geometry:
        geometry = scene.geometry.get(scene.graph[node][1])
        if isinstance(geometry, trimesh.Trimesh):
            vertices += len(geometry.vertices)
            faces += len(geometry.faces)
    where = f"the {what} scene (each part counted once per placement)"
    budget.vertices(vertices, where)
    budget.faces(faces, where)
