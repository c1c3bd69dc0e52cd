"""Output folders checked before long work: created now and proven writable, or one line saying why not."""
from __future__ import annotations

import tempfile
from pathlib import Path

from atsvo_ros.errors import AtsvoError


def ensure_writable_folder(folder: Path, named: Path, what: str, error: type[AtsvoError]) -> Path:
    """Create ``folder`` (with its parents) and prove it writable.

    ``named`` is the path the user gave (the folder itself, or a file to be written into it) and ``what``
    its option (``--out``); they make the message. Raises ``error``: a file where the folder or one of its
    parents should be, no permission, a read-only file system.
    """
    for parent in [folder, *folder.parents]:
        if parent.exists():
            if not parent.is_dir():
                where = "is" if parent == named else f"is under {parent}, which is"
                raise error(f"{what} {named} {where} a file, not a folder")
            break
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        raise error(f"{what} {named} is not writable: {exc.strerror or exc}") from None
    return folder


__all__ = ["ensure_writable_folder"]
