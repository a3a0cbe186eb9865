"""/labels: every label in use, with its number of models (the web page's filter suggestions)."""

from __future__ import annotations

from fastapi import APIRouter

from app.api.deps import CtxDep
from app.api.schemas import LabelCount, LabelsPublic
from app.services import catalog

router = APIRouter(prefix="/labels", tags=["models"])


@router.get("", response_model=LabelsPublic)
def list_labels(ctx: CtxDep) -> LabelsPublic:
    """Every label in use, by name, with its number of models."""
    return LabelsPublic(data=[LabelCount(label=label, models=n) for label, n in catalog.labels(ctx)])
