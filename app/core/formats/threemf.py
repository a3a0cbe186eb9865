"""3MF (3D printing): a zip of XML. Objects hold a mesh or components (other objects, each with a
transform, possibly in another model file of the archive); build items place objects.

Read here rather than by trimesh, whose reader walks every path of the component graph before counting
and silently stops after a fixed number of steps (a 3 KB chain took 60 s, then came out truncated). This
reader parses each object once, counts the expansion on the graph (graph.expand: cycles, depth,
placements, vertices and faces after instancing), and only then places the copies.
"""

from __future__ import annotations

import io
import posixpath
import zipfile
from dataclasses import dataclass, field

import numpy as np
from lxml import etree

from app.core.formats import graph
from app.core.formats.containers import check_members, open_zip, read_member
from app.core.meshdata import Budget, InvalidMeshError

_XML = {"resolve_entities": False, "no_network": True, "huge_tree": False, "load_dtd": False}
Key = tuple[str, str]  # (model file in the archive, object id)


@dataclass
class _Object:
    vertices: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    faces: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), dtype=np.int64))
    components: list[tuple[Key, np.ndarray]] = field(default_factory=list)  # (object, (4, 4) transform)


def read_3mf(data: bytes, budget: Budget) -> tuple[np.ndarray, np.ndarray]:
    """3MF bytes -> vertices (n, 3) float64, faces (f, 3) int64: every build item, transforms applied."""
    with open_zip(data, budget, "3MF") as archive:
        check_members(archive, "3MF")
        root = _root_model(archive)
        objects: dict[Key, _Object] = {}
        items = _parse_model(archive, root, objects, budget, build=True)
        _load_referenced(archive, objects, budget)
    if not items:
        raise InvalidMeshError("the 3MF file places nothing: its build section has no items")
    children = {k: [c for c, _ in o.components] for k, o in objects.items()}
    own = {k: graph.Totals(int(len(o.faces) > 0), len(o.vertices), len(o.faces)) for k, o in objects.items()}
    missing = {c for kids in children.values() for c in kids} | {k for k, _ in items}
    missing -= objects.keys()
    if missing:
        raise InvalidMeshError(
            f"the 3MF file refers to object {sorted(missing)[0][1]!r}, which it does not define"
        )
    total = graph.expand([k for k, _ in items], children, own, "3MF component graph")
    graph.check(total, "3MF build", budget)
    return _place(items, objects)


def _root_model(archive: zipfile.ZipFile) -> str:
    models = [n for n in archive.namelist() if n.lower().endswith(".model")]
    root = [n for n in models if n.lower().lstrip("/") == "3d/3dmodel.model"] or models[:1]
    if not root:
        raise InvalidMeshError("the 3MF archive holds no 3D model (no 3D/3dmodel.model)")
    return root[0]


def _parse_model(
    archive: zipfile.ZipFile, name: str, objects: dict[Key, _Object], budget: Budget, build: bool
) -> list[tuple[Key, np.ndarray]]:
    """Read one model file's objects into `objects`; return its build items (object, (4, 4) transform)."""
    items: list[tuple[Key, np.ndarray]] = []
    source = io.BytesIO(read_member(archive, name, "3MF"))
    declared = len(objects)
    try:
        for _, element in etree.iterparse(source, events=("end",), tag=("{*}object", "{*}build"), **_XML):
            if element.tag.endswith("build") and build:
                for item in element.iter("{*}item"):
                    items.append(((name, _attr(item, "objectid")), _transform(item)))
            elif element.tag.endswith("object"):
                declared += 1
                graph.check_declared(declared, "objects", "3MF file")
                objects[(name, _attr(element, "id"))] = _object(element, name, budget)
            element.clear()
    except etree.XMLSyntaxError as exc:
        raise InvalidMeshError(
            f"could not read the file as 3MF: its XML is invalid ({str(exc)[:120]})"
        ) from exc
    return items


def _load_referenced(archive: zipfile.ZipFile, objects: dict[Key, _Object], budget: Budget) -> None:
    """Components may name another model file of the archive (the production extension's p:path)."""
    parsed = {k[0] for k in objects}
    names = set(archive.namelist())
    while True:
        wanted = {c[0] for o in objects.values() for c, _ in o.components} - parsed
        if not wanted:
            return
        for path in wanted:
            parsed.add(path)
            if path not in names:
                raise InvalidMeshError(f"the 3MF file refers to '{path[:80]}', which is not in the archive")
            _parse_model(archive, path, objects, budget, build=False)


def _object(element: etree._Element, name: str, budget: Budget) -> _Object:
    out = _Object()
    for mesh in element.iter("{*}mesh"):
        coords = [(v.get("x"), v.get("y"), v.get("z")) for v in mesh.iter("{*}vertex")]
        budget.vertices(len(coords), "a 3MF object")
        corners = [(t.get("v1"), t.get("v2"), t.get("v3")) for t in mesh.iter("{*}triangle")]
        budget.faces(len(corners), "a 3MF object")
        try:
            vertices = np.array(coords, dtype=np.float64).reshape(-1, 3)
            faces = np.array(corners, dtype=np.int64).reshape(-1, 3)
        except (TypeError, ValueError) as exc:
            raise InvalidMeshError(
                "a 3MF vertex or triangle is missing a number or holds a non-number"
            ) from exc
        if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
            raise InvalidMeshError("a 3MF triangle refers to a vertex its object does not have")
        out.faces = np.concatenate([out.faces, faces + len(out.vertices)])
        out.vertices = np.concatenate([out.vertices, vertices])
    for component in element.iter("{*}component"):
        path = next((v for k, v in component.attrib.items() if k.endswith("path")), None)
        where = posixpath.normpath(path.lstrip("/")) if path else name
        out.components.append(((where, _attr(component, "objectid")), _transform(component)))
    return out


def _attr(element: etree._Element, key: str) -> str:
    value = element.get(key)
    if value is None:
        raise InvalidMeshError(f"a 3MF <{etree.QName(element).localname}> has no '{key}'")
    return value


def _transform(element: etree._Element) -> np.ndarray:
    """The 3MF 'transform' attribute (12 numbers, a 4 x 3 matrix for row vectors) -> (4, 4) for columns."""
    out = np.eye(4)
    if "transform" in element.attrib:
        try:
            values = np.array(element.get("transform", "").split(), dtype=np.float64)
            out[:3, :4] = values.reshape(4, 3).T
        except ValueError as exc:
            raise InvalidMeshError("a 3MF transform is not 12 numbers") from exc
        if not np.isfinite(out).all():
            raise InvalidMeshError("a 3MF transform holds a number that is not finite")
    return out


def _place(items: list[tuple[Key, np.ndarray]], objects: dict[Key, _Object]) -> tuple[np.ndarray, np.ndarray]:
    """Expand the (already counted) graph: every mesh at every placement, its transforms composed."""
    vertices, faces, offset = [], [], 0
    stack = [(key, t) for key, t in reversed(items)]
    while stack:
        key, transform = stack.pop()
        obj = objects[key]
        if len(obj.faces):
            vertices.append(obj.vertices @ transform[:3, :3].T + transform[:3, 3])
            faces.append(obj.faces + offset)
            offset += len(obj.vertices)
        stack.extend((kid, transform @ t) for kid, t in reversed(obj.components))
    if not faces:
        raise InvalidMeshError("the 3MF file holds no triangle mesh")
    return np.concatenate(vertices), np.concatenate(faces)
