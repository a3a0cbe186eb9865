"""Server-side mesh thumbnails: a pure-numpy z-buffer rasteriser + Pillow for the PNG.

No GPU, no display, no OpenGL: the service renders thumbnails inside worker or API processes on a
headless machine. The mesh is turned into its canonical view (thumbnail_view.py: principal axes, the side
with the most silhouette, upright), then seen from a 3/4 view (orthographic), fitted to the frame by its
projected bounding box, shaded with two-sided Phong-interpolated normals (key + fill light) and
anti-aliased by supersampling (the ss x ss samples of each pixel are averaged in premultiplied alpha).

Rasterising is vectorised by bucketing triangles by the size of their pixel bounding box: a bucket of
B triangles whose boxes fit in d x d pixels tests B * d * d candidate pixels at once; the nearest
fragment per pixel wins by one lexicographic sort (deterministic, unlike scattered assignment).
"""

from __future__ import annotations

import io

import numpy as np
from PIL import Image

from app.services.thumbnail_view import canonical_rotation

# A pleasant 3/4 view: turn the model 35 degrees about the vertical axis, then tilt it 20 degrees towards
# the viewer (y is up, the camera looks down -z).
_YAW = np.radians(-35.0)
_PITCH = np.radians(20.0)
_BASE_COLOUR = np.array([0.56, 0.66, 0.80])  # soft steel blue
_KEY_LIGHT = np.array([-0.45, 0.65, 0.62])  # from the upper left, in view space
_FILL_LIGHT = np.array([0.6, -0.2, 0.5])
_MARGIN = 0.06  # fraction of the frame left free on each side
_MAX_CANDIDATES = 4_000_000  # candidate pixels tested per batch (bounds memory to ~100 MB)
# candidate pixels in all (the sum of the triangles' boxes), counted before any is tested: slivers
# spanning the frame cost a box each (20k of them took minutes); a few seconds of work at most
MAX_TOTAL_CANDIDATES = 150_000_000


class RenderTooCostlyError(ValueError):
    """The mesh's triangles cover more candidate pixels than a thumbnail may test."""


def render_png(
    vertices: np.ndarray,
    faces: np.ndarray,
    size: int = 256,
    *,
    supersample: int = 3,
    background: tuple[int, int, int, int] = (255, 255, 255, 0),
) -> bytes:
    """Render a triangle mesh to a size x size RGBA PNG.

    vertices : (n, 3) float, any scale and position
    faces    : (f, 3) int, indices into vertices
    background : RGBA; the default is transparent (white where a viewer ignores alpha)
    Returns the PNG file's bytes; the same input always gives the same bytes.
    """
    rgba = render_rgba(vertices, faces, size, supersample=supersample, background=background)
    buf = io.BytesIO()
    Image.fromarray(rgba, mode="RGBA").save(buf, format="PNG", optimize=False)
    return buf.getvalue()


def render_rgba(
    vertices: np.ndarray,
    faces: np.ndarray,
    size: int = 256,
    *,
    supersample: int = 3,
    background: tuple[int, int, int, int] = (255, 255, 255, 0),
) -> np.ndarray:
    """Same as :func:`render_png` but returns the (size, size, 4) uint8 image."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
        raise ValueError("vertices must be (n, 3) and faces (f, 3)")
    if size < 8 or size > 2048:
        raise ValueError("thumbnail size must be between 8 and 2048 pixels")
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise ValueError("faces index vertices that do not exist")
    ss = max(1, int(supersample))
    big = size * ss
    colour = np.zeros((big * big, 3))
    alpha = np.zeros(big * big)
    if len(v) and len(f) and np.isfinite(v).all():
        v = (v - v.mean(axis=0)) @ canonical_rotation(v, f).T  # principal axes, most silhouette, upright
        screen, depth, view = _project(v, big)
        pix, face, bary = _rasterise(screen, depth, f, big)
        if pix.size:
            colour[pix] = _shade(view, f, face, bary)
            alpha[pix] = 1.0
    return _downsample(colour, alpha, size, ss, background)


def _rotation() -> np.ndarray:
    """(3, 3) world -> view rotation of the fixed 3/4 view."""
    cy, sy = np.cos(_YAW), np.sin(_YAW)
    cp, sp = np.cos(_PITCH), np.sin(_PITCH)
    yaw = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    pitch = np.array([[1.0, 0.0, 0.0], [0.0, cp, -sp], [0.0, sp, cp]])
    return pitch @ yaw


def _project(v: np.ndarray, big: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rotate into view space, fit the projected bounding box to the frame.

    Returns screen (n, 2) pixel coordinates (x right, y down), depth (n,) (larger = nearer),
    view (n, 3) rotated coordinates (for normals).
    """
    view = (v - v.mean(axis=0)) @ _rotation().T
    lo, hi = view[:, :2].min(axis=0), view[:, :2].max(axis=0)
    extent = float((hi - lo).max())
    scale = big * (1.0 - 2.0 * _MARGIN) / extent if extent > 0 else 1.0
    centre = (lo + hi) / 2.0
    screen = np.empty((len(v), 2))
    screen[:, 0] = (view[:, 0] - centre[0]) * scale + big / 2.0
    screen[:, 1] = big / 2.0 - (view[:, 1] - centre[1]) * scale
    return screen, view[:, 2], view


def _rasterise(
    screen: np.ndarray, depth: np.ndarray, faces: np.ndarray, big: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Z-buffer: the nearest triangle at each covered pixel centre.

    Returns pix (p,) flat pixel indices, face (p,) triangle index, bary (p, 3) barycentric weights.
    """
    tri = screen[faces]  # (f, 3, 2)
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    area2 = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    # pixels whose centres (x + 0.5, y + 0.5) fall inside each triangle's bounding box
    x0 = np.clip(np.ceil(tri[:, :, 0].min(axis=1) - 0.5), 0, big - 1).astype(np.int64)
    x1 = np.clip(np.floor(tri[:, :, 0].max(axis=1) - 0.5), 0, big - 1).astype(np.int64)
    y0 = np.clip(np.ceil(tri[:, :, 1].min(axis=1) - 0.5), 0, big - 1).astype(np.int64)
    y1 = np.clip(np.floor(tri[:, :, 1].max(axis=1) - 0.5), 0, big - 1).astype(np.int64)
    w, h = x1 - x0 + 1, y1 - y0 + 1
    live = (np.abs(area2) > 1e-12) & (w > 0) & (h > 0)
    # bucket key: box width and height, exact up to 8 pixels, then rounded up to a power of two
    kind = _size_class(w) * 4096 + _size_class(h)
    total = int((_size_class(w[live]) * _size_class(h[live])).sum())
    if total > MAX_TOTAL_CANDIDATES:
        raise RenderTooCostlyError(
            f"its triangles cover {total:,} candidate pixels, more than the {MAX_TOTAL_CANDIDATES:,} a"
            " thumbnail may test (long slivers across the frame)"
        )

    out_pix, out_face, out_bary, out_key = [], [], [], []
    for key in np.unique(kind[live]):
        bw, bh = int(key) // 4096, int(key) % 4096
        ids = np.flatnonzero(live & (kind == key))
        dy, dx = np.divmod(np.arange(bw * bh), bw)
        step = max(1, _MAX_CANDIDATES // (bw * bh))
        for s in range(0, len(ids), step):
            t = ids[s : s + step]
            px = x0[t, None] + dx[None, :]  # (B, bw*bh)
            py = y0[t, None] + dy[None, :]
            cx, cy = px + 0.5, py + 0.5
            ax, ay = a[t, 0, None], a[t, 1, None]
            bx, by = b[t, 0, None], b[t, 1, None]
            qx, qy = c[t, 0, None], c[t, 1, None]
            inv = 1.0 / area2[t, None]
            w0 = ((bx - cx) * (qy - cy) - (by - cy) * (qx - cx)) * inv
            w1 = ((qx - cx) * (ay - cy) - (qy - cy) * (ax - cx)) * inv
            w2 = 1.0 - w0 - w1
            eps = -1e-9
            ok = (w0 >= eps) & (w1 >= eps) & (w2 >= eps) & (px <= x1[t, None]) & (py <= y1[t, None])
            rows, cols = np.nonzero(ok)
            tf = t[rows]
            bary = np.stack([w0[rows, cols], w1[rows, cols], w2[rows, cols]], axis=1)
            z = (bary * depth[faces[tf]]).sum(axis=1)
            out_pix.append(py[rows, cols] * big + px[rows, cols])
            out_face.append(tf)
            out_bary.append(bary)
            out_key.append(-z)
    if not out_pix or not sum(len(p) for p in out_pix):  # no pixel centre inside any triangle (needles)
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3))
    pix = np.concatenate(out_pix)
    face = np.concatenate(out_face)
    bary = np.concatenate(out_bary)
    key = np.concatenate(out_key)
    # one int64 sort key: pixel, then depth quantised to 2**31 levels (nearest first); the stable sort
    # breaks exact ties by triangle order, so the same input always gives the same image
    span = max(float(key.max() - key.min()), 1e-300)
    rank = np.round((key - key.min()) / span * (2**31 - 1)).astype(np.int64)
    order = np.argsort(pix * 2**31 + rank, kind="stable")
    pix, first = np.unique(pix[order], return_index=True)
    winners = order[first]
    return pix, face[winners], bary[winners]


def _size_class(n: np.ndarray) -> np.ndarray:
    """(f,) box sizes -> bucket sizes: exact up to 8, else the next power of two."""
    pow2 = np.left_shift(1, np.ceil(np.log2(np.maximum(n, 1))).astype(np.int64))
    return np.where(n <= 8, np.maximum(n, 1), pow2)


def _shade(view: np.ndarray, faces: np.ndarray, face: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """(p, 3) linear RGB in [0, 1] for the winning fragments.

    view : (n, 3) view-space vertices; face (p,), bary (p, 3) from the rasteriser.
    """
    tri = view[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # (f, 3), area weighted
    vn = np.zeros_like(view)
    for k in range(3):
        for axis in range(3):
            vn[:, axis] += np.bincount(faces[:, k], weights=fn[:, axis], minlength=len(view))
    flat = _unit(fn[face])
    flat *= np.where(flat[:, 2:3] < 0, -1.0, 1.0)  # two-sided: back faces lit like front faces
    smooth = (bary[:, :, None] * vn[faces[face]]).sum(axis=1)
    smooth *= np.where((smooth * flat).sum(axis=1, keepdims=True) < 0, -1.0, 1.0)
    length = np.linalg.norm(smooth, axis=1, keepdims=True)
    n = np.where(length > 1e-12, smooth / np.maximum(length, 1e-300), flat)
    key, fill = _unit(_KEY_LIGHT[None])[0], _unit(_FILL_LIGHT[None])[0]
    diffuse = 0.72 * np.clip(n @ key, 0, None) + 0.22 * np.clip(n @ fill, 0, None)
    half = _unit((key + np.array([0.0, 0.0, 1.0]))[None])[0]
    specular = 0.18 * np.clip(n @ half, 0, None) ** 32
    rim = 0.10 * (1.0 - np.clip(n[:, 2], 0, 1)) ** 2  # soft edge light: keeps silhouettes readable
    light = 0.24 + diffuse
    return np.clip(_BASE_COLOUR[None] * light[:, None] + (specular + rim)[:, None], 0.0, 1.0)


def _unit(x: np.ndarray) -> np.ndarray:
    return x / np.maximum(np.linalg.norm(x, axis=-1, keepdims=True), 1e-300)


def _downsample(
    colour: np.ndarray, alpha: np.ndarray, size: int, ss: int, background: tuple[int, int, int, int]
) -> np.ndarray:
    """Average ss x ss samples per pixel in premultiplied alpha, composite over the background.

    colour : (big*big, 3) in [0, 1]; alpha : (big*big,) in {0, 1}. Returns (size, size, 4) uint8.
    """
    bg = np.asarray(background, dtype=np.float64) / 255.0
    pre = np.concatenate([colour * alpha[:, None], alpha[:, None]], axis=1)
    pre = pre.reshape(size, ss, size, ss, 4).mean(axis=(1, 3))
    a_fg = pre[..., 3:4]
    a_out = a_fg + bg[3] * (1.0 - a_fg)
    rgb_pre = pre[..., :3] + bg[:3] * bg[3] * (1.0 - a_fg)
    rgb = np.where(a_out > 0, rgb_pre / np.maximum(a_out, 1e-12), bg[:3])
    out = np.concatenate([rgb, a_out], axis=-1)
    return np.round(np.clip(out, 0.0, 1.0) * 255.0).astype(np.uint8)
