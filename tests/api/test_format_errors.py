"""Format errors mapped once (app/api/errors.py): one code per fault, the same on every door."""

from __future__ import annotations

import json
import struct

from fastapi.testclient import TestClient

from app.main import create_app
from tests.conftest import make_settings


def _external_buffer_glb() -> bytes:
    doc = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": 48, "uri": "x.bin"}],
        "bufferViews": [{"buffer": 0, "byteLength": 48}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "nodes": [{"mesh": 0}],
    }
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body


UNSUPPORTED = [
    ("glass.wrl", "VRML (.wrl) is not supported: export it as OBJ"),
    ("scan.xyz", "(.xyz) is a point cloud"),
]


def test_format_errors_are_one_code_on_every_door(data_dir):
    """An unsupported format: 415 unsupported_format on /models and /search alike (it was 422 invalid_input
    on one and 422 invalid_mesh on the other); a broken file of a supported format: 422 invalid_mesh,
    with the reason in words."""
    with TestClient(create_app(make_settings(data_dir))) as client:
        for door in ("/models", "/search"):
            for filename, says in UNSUPPORTED:
                r = client.post(door, files={"file": (filename, b"#VRML V2.0 utf8\n")})
                error = r.json()["error"]
                assert (r.status_code, error["code"]) == (415, "unsupported_format"), (
                    door,
                    filename,
                    r.json(),
                )
                assert says in error["message"]
            r = client.post(door, files={"file": ("scene.glb", _external_buffer_glb())})
            assert (r.status_code, r.json()["error"]["code"]) == (422, "invalid_mesh"), (door, r.json())
            assert "refers to an external file 'x.bin'" in r.json()["error"]["message"]
