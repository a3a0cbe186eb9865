"""The software renderer: size, geometry of what it draws, determinism, and bad input."""

from __future__ import annotations

import io

import numpy as np
import pytest
import trimesh
from PIL import Image

from app.services.thumbnails import _MARGIN, render_png, render_rgba


@pytest.fixture(scope="module")
def sphere() -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions=4, radius=3.0)


def _decode(png: bytes) -> np.ndarray:
    image = Image.open(io.BytesIO(png))
    assert image.format == "PNG"
    return np.asarray(image.convert("RGBA"))


@pytest.mark.parametrize("size", [64, 256])
def test_png_decodes_to_requested_size(sphere: trimesh.Trimesh, size: int) -> None:
    rgba = _decode(render_png(sphere.vertices, sphere.faces, size))
    assert rgba.shape == (size, size, 4)


def test_sphere_renders_a_centred_disc_of_the_expected_radius(sphere: trimesh.Trimesh) -> None:
    size = 256
    alpha = render_rgba(sphere.vertices, sphere.faces, size)[..., 3].astype(float) / 255.0
    radius = size / 2 * (1 - 2 * _MARGIN)  # the projected bounding box is fitted to the frame
    covered = alpha.sum()
    assert covered == pytest.approx(np.pi * radius**2, rel=0.03)
    ys, xs = np.mgrid[0:size, 0:size] + 0.5
    cx, cy = (alpha * xs).sum() / covered, (alpha * ys).sum() / covered
    assert abs(cx - size / 2) < 1.5 and abs(cy - size / 2) < 1.5
    # inside the disc fully opaque, well outside fully transparent
    r = np.hypot(xs - size / 2, ys - size / 2)
    assert alpha[r < radius - 3].min() == 1.0
    assert alpha[r > radius + 3].max() == 0.0


def test_position_and_scale_do_not_change_the_picture(sphere: trimesh.Trimesh) -> None:
    a = render_rgba(sphere.vertices, sphere.faces, 96)
    b = render_rgba(sphere.vertices * 250.0 + [10.0, -4.0, 7.0], sphere.faces, 96)
    assert np.abs(a.astype(int) - b.astype(int)).max() <= 1


def test_a_thin_shape_is_visible_and_shaded() -> None:
    capsule = trimesh.creation.capsule(height=4.0, radius=0.4)
    rgba = render_rgba(capsule.vertices, capsule.faces, 128)
    visible = rgba[..., 3] > 0
    assert visible.mean() > 0.05
    grey = rgba[visible][:, :3].astype(float).mean(axis=1)
    assert grey.max() - grey.min() > 60  # lit and shadowed sides differ: it is shaded, not a flat stencil


def test_same_input_same_bytes(sphere: trimesh.Trimesh) -> None:
    assert render_png(sphere.vertices, sphere.faces, 128) == render_png(sphere.vertices, sphere.faces, 128)


def test_face_winding_does_not_matter(sphere: trimesh.Trimesh) -> None:
    flipped = sphere.faces[:, ::-1]
    a = render_rgba(sphere.vertices, sphere.faces, 96)
    b = render_rgba(sphere.vertices, flipped, 96)
    assert np.abs(a.astype(int) - b.astype(int)).max() <= 1


def test_white_background_option(sphere: trimesh.Trimesh) -> None:
    rgba = render_rgba(sphere.vertices, sphere.faces, 64, background=(255, 255, 255, 255))
    assert (rgba[..., 3] == 255).all()
    assert (rgba[0, 0, :3] == 255).all()


def test_degenerate_mesh_gives_an_empty_image() -> None:
    v = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    rgba = render_rgba(v, np.array([[0, 1, 2]]), 32)
    assert rgba[..., 3].max() == 0


@pytest.mark.parametrize(
    ("vertices", "faces"),
    [
        (np.zeros((4, 2)), np.array([[0, 1, 2]])),
        (np.zeros((4, 3)), np.array([[0, 1, 7]])),
        (np.zeros((4, 3)), np.array([0, 1, 2])),
    ],
)
def test_bad_arrays_are_refused(vertices: np.ndarray, faces: np.ndarray) -> None:
    with pytest.raises(ValueError):
        render_png(vertices, faces)
