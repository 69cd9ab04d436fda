"""A USD file written by a process of its own, so that loading pxr overlaps the run.

Loading pxr (``Tf``, ``Vt``, ``Gf``, ``Sdf``, ``Usd`` and its schemas) takes about 0.35 s on one
core, holding the interpreter's lock throughout, so a thread cannot overlap it with anything
else the command does in Python. ``warpsim run`` therefore starts a :class:`UsdWriter` once its
scene is loaded and checked: the process forks (cheap: a few milliseconds, and the child has
the scene, the output's path and the options as they are), the child loads the USD writer
while the parent draws and simulates its swarm on the other core, then waits. The recorded
frames need no copy to reach it: the writer reserves, before the fork, shared memory for them
(``share_bytes``, an anonymous shared mapping both processes keep), the simulator records into
it (:meth:`UsdWriter.empty`, ``Simulator.run(allocate=...)``), and the child reads the same
pages. An array outside it goes through the pipe when small (the frame numbers, the radii),
else through an ``.npy`` file in a temporary folder that the child maps (frames beyond the
reserve): such a copy of the 75 MB of 200 000 spheres x 13 frames took 0.15 s in the command
(fresh pages), 0.1 to 0.4 s through a pipe. The child writes the file with the same function
as ever (:func:`warpsim.export.write_usd`, atomically) and answers the path, or the error it
raised.

The parent writes the file itself, in its own process, wherever a child would not help or
might not be safe: where ``fork`` is not the platform's (only Linux forks here), when pxr is
loaded already (a scene read from a USD stage), when other threads are running (a fork copies
only the calling thread, and another's locks with it), for a trajectory above
``HANDOFF_MAX_BYTES`` outside the shared memory (writing it takes far longer than the import
saved), and whenever the child is gone or the handoff fails (a full disk): the same file
either way.
"""

from __future__ import annotations

import dataclasses
import mmap
import multiprocessing
import shutil
import signal
import sys
import tempfile
import threading
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..trajectory import Trajectory

#: A trajectory whose arrays outside the shared memory hold more than this [bytes] is written in
#: the parent's process: their handoff through files would cost more than loading pxr, which the
#: write then dwarfs.
HANDOFF_MAX_BYTES = 1 << 30

#: An array outside the shared memory up to this size [bytes] goes through the pipe itself (the
#: frame numbers, the radii of a few hundred thousand spheres); a larger one through a file.
PICKLED_MAX_BYTES = 1 << 22

#: Alignment [bytes] of each array handed out of the shared memory (a cache line, and more than
#: any type's).
SHARED_ALIGN = 64

#: The trajectory's fields the writer reads (``events`` is not written to USD).
HANDED_FIELDS = tuple(f.name for f in dataclasses.fields(Trajectory) if f.name != "events")


def can_fork() -> bool:
    """Whether a writer process may be forked here and now: on Linux, with pxr not loaded yet
    and no other thread running."""
    return (sys.platform.startswith("linux") and "pxr" not in sys.modules
            and threading.active_count() == 1)


def _child(conn, parent_end, write: Callable[[Trajectory], Path], shared) -> None:
    """The writer process: load the USD writer, wait for one trajectory, write it, answer.

    Answers ``("ok", path)`` or ``("error", exception)``. Ctrl-C is the parent's to handle (it
    ends this process when it ends); SIGTERM unwinds (``SystemExit``), so a file being written
    is removed by the writer's own clean-up, as it is in the parent on an interrupt."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))
    parent_end.close()  # only the parent holds it now: its end closing is this end's EOF
    loaded = None
    try:
        from . import usd_write  # noqa: F401 - loads pxr while the parent simulates
    except BaseException as exc:  # reported when the file is asked for, as the parent would
        loaded = exc
    try:
        job = conn.recv()
    except EOFError:  # the parent ended without asking
        return
    if job is None:
        return
    folder, values = job
    try:
        if loaded is not None:
            raise loaded
        fields = {}
        for name, value in values.items():
            if isinstance(value, tuple) and value[0] == "shared":
                _, offset, shape, dtype, strides = value
                view = np.ndarray(shape, dtype=dtype, buffer=shared, offset=offset,
                                  strides=strides)
                view.flags.writeable = False
                fields[name] = view
            elif isinstance(value, tuple) and value[0] == "file":
                fields[name] = np.load(Path(folder) / f"{name}.npy", mmap_mode="r")
            else:
                if isinstance(value, np.ndarray):  # through the pipe: read-only as the others
                    value.flags.writeable = False
                fields[name] = value
        answer = ("ok", write(Trajectory(**fields)))
    except Exception as exc:  # noqa: BLE001 - handed to the parent, which reports it
        answer = ("error", exc)
    try:
        conn.send(answer)
    except Exception as exc:  # noqa: BLE001 - an exception that does not pickle
        conn.send(("error", RuntimeError(f"{type(answer[1]).__name__}: {answer[1]} ({exc})")))


class UsdWriter:
    """Write one trajectory with ``write`` (``write(trajectory) -> Path``), in a process forked
    now where :func:`can_fork` allows it, else in this one (module docstring).

    ``write`` is called in the child with a trajectory whose arrays are read-only views of the
    parent's, bit for bit, and without its ``events``. ``share_bytes`` [bytes] of shared memory
    are reserved for the arrays :meth:`empty` makes (with a fork only). Use it as a context
    manager, or call :meth:`close`: a child not asked for a file ends then.
    """

    def __init__(self, write: Callable[[Trajectory], Path], *, fork: bool | None = None,
                 share_bytes: int = 0):
        self._write = write
        self._process = None
        self._conn = None
        self._shared = None  # the shared memory, as bytes, and the next free offset in it
        self._used = 0
        self._busy = False  # a trajectory handed over and not answered yet
        if fork if fork is not None else can_fork():
            if share_bytes > 0:  # mapped before the fork: both processes keep the same pages
                try:
                    self._shared = np.frombuffer(mmap.mmap(-1, int(share_bytes)),
                                                 dtype=np.uint8)
                except (OSError, OverflowError, ValueError):  # no room: arrays go as files
                    self._shared = None
            context = multiprocessing.get_context("fork")
            parent_end, child_end = context.Pipe()
            process = context.Process(target=_child,
                                      args=(child_end, parent_end, write, self._shared),
                                      daemon=True, name="warpsim-usd-writer")
            process.start()
            child_end.close()
            self._process, self._conn = process, parent_end

    @property
    def forked(self) -> bool:
        """Whether a writer process is waiting for the trajectory."""
        return self._process is not None

    def empty(self, shape, dtype) -> np.ndarray:
        """An uninitialised array (``numpy.empty``'s contract), in the shared memory while it
        has room, so that the child reads it without a copy; the ``allocate`` of
        ``Simulator.run``."""
        dtype = np.dtype(dtype)
        size = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
        start = -(-self._used // SHARED_ALIGN) * SHARED_ALIGN
        if self._shared is None or self._process is None or start + size > self._shared.size:
            return np.empty(shape, dtype=dtype)
        self._used = start + size
        return self._shared[start:start + size].view(dtype).reshape(shape)

    def _in_shared(self, value: np.ndarray):
        """``("shared", offset, shape, dtype, strides)`` for an array wholly inside the shared
        memory, else None."""
        if self._shared is None or value.size == 0:
            return None
        start = value.__array_interface__["data"][0]
        reach = [s * (n - 1) for s, n in zip(value.strides, value.shape, strict=True)]
        low = start + sum(r for r in reach if r < 0)
        high = start + sum(r for r in reach if r > 0) + value.itemsize
        base = self._shared.__array_interface__["data"][0]
        if low < base or high > base + self._shared.size:
            return None
        return ("shared", start - base, value.shape, value.dtype.str, value.strides)

    def write(self, trajectory: Trajectory) -> Path:
        """Write ``trajectory`` (in the child when there is one); returns what ``write``
        returned, and raises what it raised."""
        if self._process is None:
            return self._write(trajectory)
        values = {}
        files = {}
        for name in HANDED_FIELDS:
            value = getattr(trajectory, name)
            if isinstance(value, np.ndarray):
                shared = self._in_shared(value)
                if shared is not None:
                    value = shared
                elif value.nbytes > PICKLED_MAX_BYTES:
                    files[name] = value
                    value = ("file",)
            values[name] = value
        if sum(v.nbytes for v in files.values()) > HANDOFF_MAX_BYTES:
            self.close()
            return self._write(trajectory)
        folder = None
        try:
            if files:
                folder = tempfile.mkdtemp(prefix="warpsim-usd-")
                for name, value in files.items():
                    np.save(Path(folder) / f"{name}.npy", value)
            self._busy = True
            self._conn.send((folder, values))
            kind, result = self._conn.recv()
            self._busy = False
        except (OSError, EOFError):  # a full disk, the child gone: write it here
            self.close()
            return self._write(trajectory)
        finally:
            if folder is not None:
                shutil.rmtree(folder, ignore_errors=True)
        self.close()
        if kind == "error":
            raise result
        return result

    def close(self) -> None:
        """End the child: told there is nothing to write if it still waits; stopped (SIGTERM)
        if it is writing, as on Ctrl-C during the write, so that, as in one process, the file
        being written is removed and none appears."""
        process, conn, busy = self._process, self._conn, self._busy
        self._process = self._conn = None
        self._busy = False
        if process is None:
            return
        if busy:
            process.terminate()
        else:
            try:
                conn.send(None)
            except OSError:  # it is gone already
                pass
        conn.close()
        process.join(timeout=10.0)
        if process.is_alive():
            process.kill()
            process.join()

    def __enter__(self) -> UsdWriter:
        return self

    def __exit__(self, *_exc) -> None:
        self.close()


__all__ = ["HANDOFF_MAX_BYTES", "SHARED_ALIGN", "UsdWriter", "can_fork"]
