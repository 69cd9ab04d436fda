"""Output files: check a destination before a long computation, then write it atomically (under a
temporary name in the target folder, renamed over the target in one step). The one atomic writer
of the package and its studies; standard library only (importing it never loads pxr)."""

from __future__ import annotations

import contextlib
import json
import os
import secrets
from collections.abc import Iterator
from pathlib import Path


def temporary_sibling(path: Path) -> Path:
    """An unused name next to ``path`` with its extension: ``a.usdc`` -> ``a.tmp-1f2e3d4c.usdc``.

    Keeping the real extension matters: USD and Pillow pick the file format from it. The
    extension is lower-cased (``a.USDC`` -> ``a.tmp-1f2e3d4c.usdc``) so that every library
    recognises it; the final rename keeps the name as given.
    """
    for _ in range(100):
        candidate = path.with_name(f"{path.stem}.tmp-{secrets.token_hex(4)}{path.suffix.lower()}")
        if not candidate.exists():
            return candidate
    raise FileExistsError(f"no free temporary name next to {str(path)!r}")


def check_writable(path, suffixes: tuple[str, ...] | None = None, what: str = "output") -> Path:
    """Check that a file can be written at ``path``, before the work that produces it starts.

    The check creates (and removes) an empty temporary file next to ``path``: permission bits,
    read-only or virtual file systems (``/proc``) and full quotas all show here, not after a long
    simulation. A file already at ``path`` is left untouched.

    Args:
        path: the file to be written.
        suffixes: allowed extensions, lower case with the dot (``(".usdc", ".usda")``); the
            comparison ignores case. None allows any.
        what: what the file is, for the messages (``"output"``, ``"events file"``).

    Returns:
        ``path`` as a :class:`pathlib.Path`, as given.

    Raises:
        ValueError: an empty path, a folder, or a wrong extension.
        FileNotFoundError: the folder does not exist.
        OSError: the folder is not writable (the message names the path).
    """
    text = os.fspath(path)
    if not text.strip():
        raise ValueError(f"{what} path is empty")
    path = Path(text)
    if suffixes is not None and path.suffix.lower() not in suffixes:
        raise ValueError(f"{what} must end in {' or '.join(suffixes)}, got {text!r}")
    if path.is_dir():
        raise ValueError(f"{what} {text!r} is a folder, not a file")
    folder = path.parent
    if not folder.is_dir():
        raise FileNotFoundError(f"folder of {what} {text!r} does not exist")
    probe = temporary_sibling(path)
    try:
        with open(probe, "xb"):
            pass
    except OSError as exc:
        raise OSError(f"cannot write {what} {text!r}: {exc.strerror or exc}") from None
    finally:
        with contextlib.suppress(OSError):
            probe.unlink()
    return path


@contextlib.contextmanager
def atomic_output(path: Path) -> Iterator[Path]:
    """Yield a temporary path to write; on success it replaces ``path`` in one rename.

    On any error (in the caller's block or in the rename) the temporary file is removed and a
    file already at ``path`` is left untouched; the error propagates.

    Args:
        path: final file name; its folder must exist (the temporary file is created there so
            that :func:`os.replace` is a same-filesystem rename).
    """
    path = Path(path)
    tmp = temporary_sibling(path)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise


def write_bytes(path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (:func:`atomic_output`), creating its folder."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_output(path) as tmp:
        tmp.write_bytes(data)
    return path


def write_json(path, data) -> Path:
    """Write ``data`` as indented JSON (numpy scalars as floats) to ``path`` atomically,
    creating its folder."""
    return write_bytes(path, (json.dumps(data, indent=1, default=float) + "\n").encode())
