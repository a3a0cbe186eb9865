"""RoomDep: routes that store something first check the data directory's room (services/space.py)."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request

from app.services import space


def require_room(request: Request) -> None:
    """507 before the body is read when the disk is at its floor or the quota is used up; the declared
    body size counts as what is about to be written."""
    settings = request.app.state.settings
    declared = request.headers.get("content-length", "")
    incoming = int(declared) if declared.isdigit() and len(declared) < 16 else 0
    space.check_room(settings.data_dir, settings.storage, incoming)


RoomDep = Annotated[None, Depends(require_room)]
