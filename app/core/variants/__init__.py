"""Variants and duplicates: a cheap fingerprint to find candidates, a geometric verification that says
how two meshes are related (identical, moved, rescaled, mirrored, retriangulated, part of / contains,
or only similar), with the distances, scale and transform behind it. Pure numerics."""

from app.core.variants.fingerprint import DIM, FINGERPRINT_VERSION, fingerprint
from app.core.variants.prepared import Prepared
from app.core.variants.relate import EXACT, RELATIONS, Evidence, relate, verify

__all__ = [
    "DIM", "EXACT", "FINGERPRINT_VERSION", "RELATIONS", "Evidence", "Prepared",
    "fingerprint", "relate", "verify",
]
