"""`snapshot(root)`: every entry under a directory, to check that a command left it unchanged."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

__all__ = ["snapshot"]


def snapshot(root: Path) -> dict[str, Any]:
    """Every entry under ``root``: kind, and the bytes of regular files."""
    if not root.exists() and not root.is_symlink():
        return {}
    out: dict[str, Any] = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in sorted(dirnames + filenames):
            p = Path(dirpath) / name
            rel = str(p.relative_to(root))
            if p.is_symlink():
                out[rel] = ("link", os.readlink(p))
            elif p.is_file():
                out[rel] = ("file", p.read_bytes())
            else:
                out[rel] = ("other", p.stat().st_mode)
    return out
