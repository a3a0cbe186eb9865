"""trimesh results (a Trimesh or a Scene of them) -> raw arrays, with transforms baked."""

from __future__ import annotations

import io

import numpy as np
import trimesh

from app.core.meshdata import InvalidMeshError


def load_with_trimesh(data: bytes, file_type: str, what: str) -> tuple[np.ndarray, np.ndarray]:
    """Parse with trimesh (no processing) and flatten: every triangle mesh of the scene, node transforms
    applied, in one (vertices (n, 3) float64, faces (f, 3) int64) pair."""
    try:
        loaded = trimesh.load(io.BytesIO(data), file_type=file_type, process=False)
        return scene_arrays(loaded, what)
    except InvalidMeshError:
        raise
    except Exception as exc:  # trimesh and its helpers raise many types for corrupt files
        raise InvalidMeshError(f"could not read the file as {what}: {short(exc)}") from exc


def scene_arrays(loaded: object, what: str) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(loaded, trimesh.Scene):
        # dump() places a copy of each geometry at every node that refers to it, transforms applied
        geometry = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh) and len(g.faces)]
        if not geometry:
            raise InvalidMeshError(f"the {what} file holds no triangle mesh (only points, lines or nothing)")
        loaded = trimesh.util.concatenate(geometry) if len(geometry) > 1 else geometry[0]
    if isinstance(loaded, trimesh.PointCloud):
        raise InvalidMeshError("the mesh has no faces (a point cloud is not a surface)")
    if not isinstance(loaded, trimesh.Trimesh):
        raise InvalidMeshError(f"the {what} file holds no triangle mesh")
    return np.asarray(loaded.vertices, dtype=np.float64), np.asarray(loaded.faces, dtype=np.int64)


def short(exc: Exception) -> str:
    """One line of an exception for a user: its first line, at most 200 characters."""
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return text[:200]
