"""Loading, validation with user-readable errors, cleaning, and the resolution policy."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from app.core.mesh import (
    InvalidMeshError,
    Mesh,
    clean,
    detect_format,
    load_mesh,
    validate,
)
from app.core.resolution import to_resolution

TETRA_V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
TETRA_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def obj_bytes(vertices, faces) -> bytes:
    lines = [f"v {x} {y} {z}" for x, y, z in vertices] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    return ("\n".join(lines) + "\n").encode()


@pytest.mark.parametrize("fmt", ["obj", "off", "ply", "stl", "glb", "gltf", "3mf"])
def test_every_supported_format_round_trips(fmt):
    sphere = trimesh.creation.icosphere(subdivisions=2)
    data = sphere.export(file_type=fmt, **({"embed_buffers": True} if fmt == "gltf" else {}))
    data = data["model.gltf"] if isinstance(data, dict) else data
    mesh = load_mesh(data if isinstance(data, bytes) else data.encode(), file_type=fmt)
    assert mesh.n_vertices == len(sphere.vertices)  # STL's duplicated corners are merged again
    assert np.isclose(mesh.area(), sphere.area, rtol=1e-5)


def test_load_from_path_uses_the_extension(tmp_path, shrec_mesh):
    path = tmp_path / "tetra.OBJ"
    path.write_bytes(obj_bytes(TETRA_V, TETRA_F))
    assert load_mesh(path).n_faces == 4


@pytest.mark.parametrize(
    ("data", "fmt", "message"),
    [
        (b"", "obj", "the file is empty"),
        (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n", "obj", "no faces"),
        (obj_bytes(TETRA_V, TETRA_F), "dwg", "unsupported mesh format"),
        (b"\x00\xff garbage \x13\x37" * 50, "ply", "could not read the file as PLY"),
    ],
)
def test_bad_files_raise_with_a_readable_message(data, fmt, message):
    with pytest.raises(InvalidMeshError, match=message):
        load_mesh(data, file_type=fmt)


@pytest.mark.parametrize(
    ("vertices", "faces", "message"),
    [
        (TETRA_V, np.zeros((0, 3), int), "no faces"),
        (np.where(np.arange(12).reshape(4, 3) == 4, np.nan, TETRA_V), TETRA_F, "non-finite"),
        (np.where(np.arange(12).reshape(4, 3) == 4, np.inf, TETRA_V), TETRA_F, "non-finite"),
        (TETRA_V[:3], np.array([[0, 1, 2]]), "too few vertices"),
        (TETRA_V, np.array([[0, 1, 7], [0, 1, 2]]), "does not exist"),
        (np.column_stack([np.arange(4.0), np.zeros(4), np.zeros(4)]), TETRA_F, "zero total area"),
    ],
)
def test_validate_names_the_problem(vertices, faces, message):
    with pytest.raises(InvalidMeshError, match=message):
        validate(vertices, faces)


def test_clean_merges_duplicates_and_drops_degenerate_and_unreferenced():
    v = np.vstack([TETRA_V, TETRA_V[:1], [[9.0, 9, 9]]])  # vertex 4 duplicates 0; vertex 5 unused
    f = np.vstack([TETRA_F, [[4, 1, 3]], [[0, 0, 1]]])  # a duplicate face through the copy; a degenerate one
    out = clean(Mesh(v, f))
    assert out.n_vertices == 4 and out.n_faces == 4


def test_clean_drops_debris_components_but_keeps_large_ones():
    big = trimesh.creation.icosphere(subdivisions=3)
    other = big.copy()
    other.apply_translation([5, 0, 0])
    crumb = trimesh.creation.icosphere(subdivisions=0, radius=0.01)
    crumb.apply_translation([0, 5, 0])
    tm = trimesh.util.concatenate([big, other, crumb])
    out = clean(Mesh(np.asarray(tm.vertices), np.asarray(tm.faces)))
    assert out.n_vertices == 2 * len(big.vertices)


def test_detect_format():
    assert detect_format("Chair.PLY") == "ply" and detect_format("glb") == "glb"
    with pytest.raises(InvalidMeshError):
        detect_format("model.fbx")


@pytest.mark.parametrize("target", [1000, 3000])
def test_resolution_policy_brings_coarse_and_fine_meshes_near_the_target(shrec_mesh, target):
    out = to_resolution(shrec_mesh, target)
    assert target / 1.5 <= out.n_vertices <= target * 1.5
    # midpoint subdivision adds samples on the same surface: area and extent are unchanged, and
    # every original vertex is still a vertex, where it was (Loop would shrink the mesh by 13-16 %)
    assert out.area() == pytest.approx(shrec_mesh.area(), rel=1e-9)
    assert np.allclose(np.ptp(out.vertices, axis=0), np.ptp(shrec_mesh.vertices, axis=0), rtol=1e-9)
    assert np.allclose(out.vertices[: shrec_mesh.n_vertices], shrec_mesh.vertices)
    fine = to_resolution(out, 400)  # quadric decimation: the shape survives within a few percent
    assert 400 / 1.5 <= fine.n_vertices <= 400 * 1.5
    assert 0.8 < fine.area() / out.area() <= 1.05
    assert np.allclose(np.ptp(fine.vertices, axis=0), np.ptp(out.vertices, axis=0), rtol=0.1)


def test_loop_subdivision_shrinks_a_coarse_mesh_which_is_why_midpoint_is_the_default(shrec_mesh):
    loop = to_resolution(shrec_mesh, 1000, subdivision="loop")
    assert loop.n_vertices == to_resolution(shrec_mesh, 1000).n_vertices  # same sampling density
    # Loop's limit surface lies inside the control mesh: a 500-face mesh loses 13-16 % of its area
    assert 0.75 < loop.area() / shrec_mesh.area() < 0.95
    with pytest.raises(ValueError, match="subdivision"):
        to_resolution(shrec_mesh, 1000, subdivision="butterfly")


def test_taubin_smoothing_removes_noise_without_shrinking(random_rotation):
    from app.core.smoothing import taubin

    def smooth(mesh: Mesh, steps: int) -> Mesh:
        return taubin(mesh, steps, "uniform")

    sphere = trimesh.creation.icosphere(subdivisions=3)
    rng = np.random.default_rng(0)
    unit = np.asarray(sphere.vertices)
    noisy = Mesh(unit * (1.0 + 0.03 * rng.standard_normal((len(unit), 1))), np.asarray(sphere.faces))
    out = smooth(noisy, 40)
    radius_before = np.linalg.norm(noisy.vertices, axis=1)
    radius_after = np.linalg.norm(out.vertices, axis=1)
    assert radius_after.std() < radius_before.std() / 3  # the noise is mostly gone
    assert abs(radius_after.mean() - 1.0) < 0.02  # and the sphere kept its size (λ|μ does not shrink)
    assert smooth(noisy, 0) is noisy
    # linear in the coordinates: smoothing commutes with a rotation
    r = random_rotation(4)
    rotated = smooth(Mesh(noisy.vertices @ r.T, noisy.faces), 40)
    assert np.allclose(rotated.vertices, out.vertices @ r.T, atol=1e-9)


# load_mesh's refusals, word for word.


TETRA_OBJ = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"


def _message(*args, **kwargs) -> str:
    with pytest.raises(InvalidMeshError) as info:
        load_mesh(*args, **kwargs)
    return str(info.value)


def test_bytes_without_a_file_type_are_refused_in_words():
    assert _message(TETRA_OBJ) == "the mesh format is unknown: give a file name with an extension"


def test_an_empty_file_is_refused_in_words():
    assert _message(b"", "obj") == "the file is empty"


def test_a_mesh_over_the_vertex_limit_after_welding_says_both_numbers():
    assert load_mesh(TETRA_OBJ, "obj", max_vertices=4).n_vertices == 4  # at the limit
    assert _message(TETRA_OBJ, "obj", max_vertices=3) == (
        "the mesh has 4 vertices once duplicates are welded, more than the limit of 3"
    )
