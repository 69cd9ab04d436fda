"""A generic sweep: one Dask task per item (many scenes or settings at once), results in order."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterable

from .. import validation as check
from .cluster import CONNECT_TIMEOUT, WORKERS_RENAMED, client_for, require_dask


def sweep(function: Callable, items: Iterable, *, client=None, processes: int | None = None,
          progress: bool = True, timeout: float = CONNECT_TIMEOUT, workers=None) -> list:
    """``[function(item) for item in items]``, one Dask task per item, results in order.

    For many scenes or settings at once, such as the accuracy study of several scenes
    (``sweep(warpsim.analysis.accuracy.main, [["room", "--out", "acc/room"], ...], client=...)``).
    ``function`` must be importable or picklable by cloudpickle on the workers.

    Args:
        function: called once per item, on a worker.
        items: the arguments, one per task.
        client: as in :func:`run`: None in this process, ``"local"``, an address or a
            ``distributed.Client``.
        processes: Dask worker processes of a ``"local"`` cluster (default: one per core).
        progress: a tqdm bar over the items.
        timeout: seconds to wait for a scheduler at an address [s].
        workers: removed (it was ``processes``); passing it is an error that says so.

    Returns:
        The results, in the order of ``items``.

    Raises:
        ValueError: an item's task failed (the message names the item's position).
        TypeError: ``workers`` given (renamed ``processes``).
    """
    if workers is not None:
        raise TypeError(WORKERS_RENAMED.format(what="sweep"))
    items = list(items)
    if not callable(function):
        raise ValueError(f"function must be callable, got {type(function).__name__}")
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(items), unit="task", file=sys.stderr, dynamic_ncols=True)
    try:
        if client is None:
            results = []
            for k, item in enumerate(items):
                try:
                    results.append(function(item))
                except Exception as exc:
                    raise ValueError(f"sweep item {k} ({item!r}) failed: "
                                     f"{' '.join(str(exc).split())}") from exc
                if bar is not None:
                    bar.update(1)
            return results
        require_dask()
        from distributed import as_completed

        with client_for(client, processes, check.scalar("timeout", timeout, positive=True)) as c:
            futures = c.map(function, items, pure=False)
            index = {f.key: k for k, f in enumerate(futures)}
            results = [None] * len(items)
            try:
                for future in as_completed(futures):
                    k = index[future.key]
                    try:
                        results[k] = future.result()
                    except Exception as exc:
                        raise ValueError(f"sweep item {k} ({items[k]!r}) failed: "
                                         f"{' '.join(str(exc).split())}") from exc
                    if bar is not None:
                        bar.update(1)
            finally:
                for future in futures:
                    future.cancel()
            return results
    finally:
        if bar is not None:
            bar.close()
