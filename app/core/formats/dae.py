"""COLLADA (.dae, or a zipped .zae): the visual scene's triangles with node transforms (trimesh +
pycollada), after counting what the node graph expands to.

A node places geometries (instance_geometry), nests nodes, and places library nodes by reference
(instance_node): a DAG that trimesh expands into a copy per path, with 3 vertices per triangle. The
counts come from the XML's declarations (each primitive's `count`, a polylist's `vcount`) before
pycollada or trimesh build anything.
"""

from __future__ import annotations

import io
import posixpath
import zipfile

import numpy as np
from lxml import etree

from app.core.formats import graph
from app.core.formats.containers import open_zip, read_member
from app.core.formats.scene import load_with_trimesh
from app.core.meshdata import Budget, InvalidMeshError

# trimesh builds one mesh per COLLADA placement (~1.5 ms each): 2,000 placements read in ~3 s
MAX_PLACEMENTS = 2_000
_XML = {"resolve_entities": False, "no_network": True, "huge_tree": False, "load_dtd": False}


def read_dae(data: bytes, budget: Budget) -> tuple[np.ndarray, np.ndarray]:
    """COLLADA bytes (XML, or a zip holding one .dae) -> vertices (n, 3) float64, faces (f, 3) int64."""
    if zipfile.is_zipfile(io.BytesIO(data)):  # pycollada would unpack it unchecked
        data = _unzip(data, budget)
    count_scene(data, budget)
    return load_with_trimesh(data, "dae", "COLLADA", budget)


def _unzip(data: bytes, budget: Budget) -> bytes:
    with open_zip(data, budget, "COLLADA") as archive:
        names = [
            n for n in archive.namelist() if n.lower().endswith(".dae") and not n.startswith("__MACOSX/")
        ]
        if "manifest.xml" in archive.namelist():  # a .zae names its root document
            root = etree.fromstring(read_member(archive, "manifest.xml", "COLLADA"), etree.XMLParser(**_XML))
            named = (root.findtext("{*}dae_root") or root.findtext("dae_root") or "").strip()
            names = [posixpath.normpath(named.lstrip("./"))] if named else names
        if len(names) != 1 or names[0] not in archive.namelist():
            raise InvalidMeshError("the zipped COLLADA file must hold exactly one .dae document")
        return read_member(archive, names[0], "COLLADA")


def count_scene(data: bytes, budget: Budget) -> graph.Totals:
    """Totals of the scene's expansion from the XML alone; InvalidMeshError when over the limits."""
    try:
        root = etree.fromstring(data, etree.XMLParser(**_XML))
    except (etree.XMLSyntaxError, ValueError) as exc:
        raise InvalidMeshError(
            f"could not read the file as COLLADA: its XML is invalid ({str(exc)[:120]})"
        ) from exc
    if root is None:
        raise InvalidMeshError("could not read the file as COLLADA: it is empty")
    faces = {g.get("id"): _faces(g) for g in root.iter("{*}geometry")}
    graph.check_declared(len(faces), "geometries", "COLLADA file")
    nodes = list(root.iter("{*}node"))
    graph.check_declared(len(nodes), "nodes", "COLLADA file")
    index = {node: i for i, node in enumerate(nodes)}
    by_id = {node.get("id"): i for i, node in enumerate(nodes) if node.get("id")}
    children: dict[int, list[int]] = {}
    own: dict[int, graph.Totals] = {}
    for i, node in enumerate(nodes):
        kids = [index[c] for c in node.iterchildren("{*}node")]
        kids += [by_id[r] for r in _refs(node, "instance_node") if r in by_id]
        children[i] = kids
        placed = [faces[r] for r in _refs(node, "instance_geometry") if r in faces]
        own[i] = graph.Totals(sum(f > 0 for f in placed), 3 * sum(placed), sum(placed))
    total = graph.expand(_roots(root, index), children, own, "COLLADA node graph")
    graph.check(total, "COLLADA scene", budget, MAX_PLACEMENTS)
    return total


def _refs(node: etree._Element, tag: str) -> list[str]:
    return [(c.get("url") or "").lstrip("#") for c in node.iterchildren("{*}" + tag)]


def _roots(root: etree._Element, index: dict) -> list[int]:
    """The top nodes of the scene's visual scene (every visual scene when none is named)."""
    scenes = {s.get("id"): s for s in root.iter("{*}visual_scene")}
    named = [(i.get("url") or "").lstrip("#") for i in root.iter("{*}instance_visual_scene")]
    chosen = [scenes[n] for n in named if n in scenes] or list(scenes.values())
    return [index[n] for s in chosen for n in s.iterchildren("{*}node")]


def _faces(geometry: etree._Element) -> int:
    """Triangles a geometry's primitives declare (a polylist's polygons fanned: vcount - 2 each)."""
    total = 0
    for primitive in geometry.iter("{*}triangles", "{*}polylist", "{*}polygons"):
        count = _count(primitive)
        vcount = primitive.find("{*}vcount")
        if vcount is not None and vcount.text and vcount.text.strip():
            try:
                sizes = np.array(vcount.text.split(), dtype=np.int64)
            except (ValueError, OverflowError) as exc:
                raise InvalidMeshError(
                    "a COLLADA polylist's vcount holds something that is not a number"
                ) from exc
            count = int(np.clip(sizes - 2, 0, None).sum())
        total += count
    return total


def _count(element: etree._Element) -> int:
    text = element.get("count", "0").strip()
    if not text.isdigit() or len(text) > 12:
        raise InvalidMeshError(
            f"a COLLADA <{etree.QName(element).localname}> count is not a whole number ({text[:20]!r})"
        )
    return int(text)
