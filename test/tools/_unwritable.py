"""The ``unwritable_dir`` fixture of the output-path tests (import it into a test module to use it)."""
from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest


@pytest.fixture()
def unwritable_dir(tmp_path) -> Iterator[Path]:
    """An existing folder nobody may write into: read-only mode, or immutable (``chattr +i``) for root, who
    ignores the mode bits. Skips the test when neither can be made here."""
    d = tmp_path / "unwritable"
    d.mkdir()
    chattr = shutil.which("chattr")
    immutable = False
    if os.geteuid() == 0:
        immutable = chattr is not None and subprocess.run([chattr, "+i", str(d)], capture_output=True).returncode == 0
    else:
        d.chmod(0o555)
    try:
        try:
            with tempfile.TemporaryFile(dir=d):
                pass
        except OSError:
            yield d
        else:
            pytest.skip("cannot make an unwritable folder here (root without chattr)")
    finally:
        if immutable:
            subprocess.run([chattr, "-i", str(d)], check=True)
        d.chmod(0o755)
