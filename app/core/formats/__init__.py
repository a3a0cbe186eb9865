"""Mesh file formats: which extensions are read, and one entry point, parse(bytes) -> raw arrays.

Each reader checks the counts a file declares against a Budget before allocating, refuses a file whose
declared counts and content disagree (truncated or padded), and returns raw (vertices, faces) arrays:
duplicates, degenerate faces and debris are left to app/core/cleaning.py.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from app.core.formats.containers import is_zip, open_zip
from app.core.formats.dae import read_dae
from app.core.formats.gltf import read_glb, read_gltf, read_zip
from app.core.formats.obj import read_obj
from app.core.formats.off import read_off
from app.core.formats.other import read_drc
from app.core.formats.ply import read_ply
from app.core.formats.stl import read_stl
from app.core.formats.threemf import read_3mf
from app.core.meshdata import Budget, InvalidMeshError, UnsupportedFormatError

Reader = Callable[[bytes, Budget], tuple[np.ndarray, np.ndarray]]

READERS: dict[str, Reader] = {
    "obj": read_obj,
    "off": read_off,
    "ply": read_ply,
    "stl": read_stl,
    "glb": read_glb,
    "gltf": read_gltf,
    "zip": read_zip,
    "3mf": read_3mf,
    "dae": read_dae,
    "drc": read_drc,
}
SUPPORTED_FORMATS: tuple[str, ...] = tuple(READERS)
CONVERT_TO = "export it as OBJ, PLY, STL, GLB or 3MF"
POINT_CLOUD = (
    "is a point cloud, and shapebag needs a surface: reconstruct one (e.g. Poisson) and " + CONVERT_TO
)
# formats people have that shapebag does not read: extension -> (name, what to do)
UNSUPPORTED: dict[str, tuple[str, str]] = {
    **{ext: ("VRML", CONVERT_TO) for ext in ("wrl", "vrml")},
    "x3d": ("X3D", CONVERT_TO),
    "ctm": ("OpenCTM", CONVERT_TO),
    **{ext: ("VTK", CONVERT_TO) for ext in ("vtp", "vtk", "vtu")},
    "fbx": ("FBX", CONVERT_TO),
    "blend": ("Blender", CONVERT_TO),
    "3ds": ("3D Studio", CONVERT_TO),
    "dxf": ("DXF", CONVERT_TO),
    "dwg": ("AutoCAD DWG", CONVERT_TO),
    **{ext: ("USD", CONVERT_TO) for ext in ("usd", "usda", "usdc", "usdz")},
    **{ext: ("STEP/IGES CAD", "tessellate it and " + CONVERT_TO) for ext in ("step", "stp", "iges", "igs")},
    "amf": ("AMF", CONVERT_TO),
    "skp": ("SketchUp", CONVERT_TO),
    **{ext: ("a point-cloud format", POINT_CLOUD) for ext in ("xyz", "pts", "pcd", "las", "laz", "e57")},
}


def detect_format(name_or_type: str) -> str:
    """'chair.OBJ' / 'obj' / '.obj' / 'tree.gltf.glb' -> 'obj' / 'obj' / 'obj' / 'glb'.

    Raises UnsupportedFormatError (an InvalidMeshError) naming the format and what to convert to.
    """
    ext = name_or_type.rsplit(".", 1)[-1].lower().strip()
    if ext in READERS:
        return ext
    if ext in UNSUPPORTED:
        name, todo = UNSUPPORTED[ext]
        verb = "" if todo is POINT_CLOUD else "is not supported: "
        raise UnsupportedFormatError(f"unsupported mesh format: {name} (.{ext}) {verb}{todo}")
    raise UnsupportedFormatError(
        f"unsupported mesh format {ext[:20]!r}: use one of "
        + ", ".join(f".{e}" for e in SUPPORTED_FORMATS)
        + " (.zip: a glTF with its .bin)"
    )


ZIPPED = ("zip", "3mf", "dae")  # formats that may be zip archives (a .dae: a zipped .zae)


def parse(data: bytes, file_type: str, budget: Budget) -> tuple[np.ndarray, np.ndarray]:
    """bytes -> vertices (n, 3) float64, faces (f, 3) int64, as the file has them (not yet cleaned).

    Bytes that are a zip under another name go through the same capped reader as a .zip (a bomb, an
    unsupported method or version is named as such), then are refused: no other reader unpacks.
    """
    if file_type not in ZIPPED and is_zip(data) and not _is_binary_stl(data, file_type):
        open_zip(data, budget, f".{file_type}").close()
        raise InvalidMeshError(
            f"the .{file_type} file is a zip archive: unzip it and upload the file inside"
            " (a glTF with its files may be uploaded as one .zip)"
        )
    return READERS[file_type](data, budget)


def _is_binary_stl(data: bytes, file_type: str) -> bool:
    """A binary STL's 80-byte header is free text and may start like a zip; its size then gives it away."""
    return (
        file_type == "stl"
        and len(data) >= 84
        and len(data) == 84 + 50 * int.from_bytes(data[80:84], "little")
    )
