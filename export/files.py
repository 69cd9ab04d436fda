"""Atomic file output: write under a temporary name in the target folder, then rename."""

from __future__ import annotations

import contextlib
import os
import secrets
from collections.abc import Iterator
from pathlib import Path


def temporary_sibling(path: Path) -> Path:
    """An unused name next to ``path`` with its extension: ``a.usdc`` -> ``a.tmp-1f2e3d4c.usdc``.

    Keeping the real extension matters: USD picks the file format (text or binary) from it.
    """
    for _ in range(100):
        candidate = path.with_name(f"{path.stem}.tmp-{secrets.token_hex(4)}{path.suffix}")
        if not candidate.exists():
            return candidate
    raise FileExistsError(f"no free temporary name next to {path}")


@contextlib.contextmanager
def atomic_output(path: Path) -> Iterator[Path]:
    """Yield a temporary path to write; on success it replaces ``path`` in one rename.

    On any error (in the caller's block or in the rename) the temporary file is removed and a
    file already at ``path`` is left untouched; the error propagates.

    Args:
        path: final file name; its folder must exist (the temporary file is created there so
            that :func:`os.replace` is a same-filesystem rename).
    """
    tmp = temporary_sibling(path)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise
