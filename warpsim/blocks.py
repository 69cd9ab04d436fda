"""Long host-side passes over the spheres cut into blocks of rows spread over the cores, and
random streams that start where a serial draw would be at a given row.

A pass over millions of spheres in whole-array NumPy makes a fresh temporary array per
operation, and touching fresh memory the first time is most of its cost; NumPy also lets go
of the GIL inside its loops. A pass done block by block (:func:`for_row_blocks`) reuses its few
small temporaries from one block to the next and runs its blocks on every core. It gives the
same bits as the whole-array pass as long as each row's result depends on that row alone, in
the same order of operations (element-wise arithmetic; the blocks of a random draw start where
the serial draw would be: :func:`stream_at`).
"""

from __future__ import annotations

import functools
import hashlib
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

import numpy as np

from .cores import host_cores

T = TypeVar("T")

ROW_BLOCK = 1 << 16
"""Rows per block (65 536): a block's float64 (rows, 3) temporary is 1.5 MiB, small enough to
be reused from the allocator, large enough that NumPy's per-call overhead is lost in it."""


def row_blocks(n: int, block: int | None = None) -> list[slice]:
    """The consecutive row slices ``[0, block), [block, 2 block), ...`` covering ``n`` rows
    (none for ``n = 0``)."""
    size = ROW_BLOCK if block is None else block
    return [slice(start, min(start + size, n)) for start in range(0, n, size)]


def map_row_blocks(n: int, work: Callable[[slice], T], block: int | None = None) -> list[T]:
    """``[work(rows) for rows in row_blocks(n, block)]``, the blocks on up to one thread per
    core (inline when there is one block or one core): ``work`` must write only its own rows.
    The first exception any block raises is raised here once every block is done."""
    blocks = row_blocks(n, block)
    threads = min(len(blocks), host_cores())
    if threads <= 1:
        return [work(rows) for rows in blocks]
    with ThreadPoolExecutor(threads) as pool:
        futures = [pool.submit(work, rows) for rows in blocks]
        return [future.result() for future in futures]


def for_row_blocks(n: int, work: Callable[[slice], object], block: int | None = None) -> None:
    """:func:`map_row_blocks` for a ``work`` that writes its rows' results itself."""
    map_row_blocks(n, work, block)


def copy_rows(out: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``out[:] = values`` for ``values`` with ``out``'s rows (cast to ``out``'s type as NumPy
    casts), in blocks of rows on every core; returns ``out``."""
    if values.shape[:1] != out.shape[:1]:
        raise ValueError(f"copy_rows: {values.shape[0]} rows into {out.shape[0]}")

    def copy(rows: slice) -> None:
        out[rows] = values[rows]

    for_row_blocks(out.shape[0], copy)
    return out


def fill_rows(out: np.ndarray, row) -> np.ndarray:
    """``out[:] = row``, one row (or value) for every row, in blocks of rows on every core;
    returns ``out``."""
    def fill(rows: slice) -> None:
        out[rows] = row

    for_row_blocks(out.shape[0], fill)
    return out


def stream_at(state: dict, offset: int) -> np.random.Generator:
    """A generator whose next draws are those a generator in ``state`` (its
    ``bit_generator.state``) gives after ``offset`` 64-bit draws: one per float64 of
    ``uniform`` or ``random``, so a block of rows starting at row ``lo`` of an ``(n, k)`` draw
    starts at ``offset = k lo``. The generator in ``state`` is not changed. For PCG64, NumPy's
    default and every draw's here (its ``advance`` counts 64-bit outputs)."""
    bit_generator = getattr(np.random, state["bit_generator"])()
    bit_generator.state = state
    bit_generator.advance(offset)
    return np.random.Generator(bit_generator)


def row_streams(rng: np.random.Generator, n: int) -> tuple[Callable, Callable]:
    """The generators of a random pass over ``n`` rows in blocks (:func:`for_row_blocks`):
    ``(stream, done)``, ``stream(offset)`` the generator whose next draws are those ``rng``
    gives after ``offset`` 64-bit draws, ``done(count)`` leaving ``rng`` where a pass of
    ``count`` draws leaves it.

    Over several blocks, ``stream`` is :func:`stream_at` from ``rng``'s state and ``done``
    advances ``rng``. Over one block (``n <= ROW_BLOCK``: the block of a sharded draw), the
    pass asks for its streams in the order of the serial draw, each where the one before
    ended, so ``stream`` is ``rng`` itself and ``done`` nothing: the same draws, without a
    generator made per stream (about 20 us each)."""
    if n <= ROW_BLOCK:
        return (lambda offset: rng), (lambda count: None)
    state = rng.bit_generator.state
    return (lambda offset: stream_at(state, offset)), rng.bit_generator.advance


def uniform_rows(rng: np.random.Generator, low, high, n: int) -> np.ndarray:
    """``rng.uniform(low, high, size=n)`` bit for bit, the rows drawn in blocks on every core
    (each block from :func:`stream_at`), ``rng`` left where that draw leaves it."""
    stream, done = row_streams(rng, n)
    out = np.empty(n)

    def block(rows: slice) -> None:
        out[rows] = stream(rows.start).uniform(low, high, size=rows.stop - rows.start)

    for_row_blocks(n, block)
    done(n)
    return out


def any_rows(n: int, test: Callable[[slice], np.ndarray]) -> bool:
    """Whether ``test(rows)`` (a boolean array for those rows) holds anywhere, the blocks of
    rows on every core."""
    return any(bool(np.any(hit)) for hit in map_row_blocks(n, test))


def digest(*arrays: np.ndarray) -> bytes:
    """A SHA-256 digest of the arrays: each one's dtype, shape and bytes (C order), its blocks
    of rows hashed on every core and their digests hashed in order, so that any change of a
    value, of the order of the rows or of a shape changes it (but for a collision of
    SHA-256)."""
    whole = hashlib.sha256()
    for array in arrays:
        array = np.ascontiguousarray(array)
        whole.update(f"{array.dtype.str}{array.shape}".encode())
        rows = (array.reshape(array.shape[0], int(np.prod(array.shape[1:])))
                if array.ndim else array.reshape(1, 1))
        for part in map_row_blocks(rows.shape[0], functools.partial(_block_digest, rows)):
            whole.update(part)
    return whole.digest()


def _block_digest(rows: np.ndarray, block: slice) -> bytes:
    """The SHA-256 of the bytes of ``rows[block]`` (C-contiguous rows)."""
    return hashlib.sha256(rows[block]).digest()
