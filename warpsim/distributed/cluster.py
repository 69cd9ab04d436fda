"""Dask clients for the sharded run and the sweep: a LocalCluster, a scheduler address or a
given ``distributed.Client``; dask is an optional extra, imported only here and only when used.
"""

from __future__ import annotations

import contextlib

from .. import validation as check

CONNECT_TIMEOUT = 10.0
"""Seconds to wait for a Dask scheduler before the error [s]."""

DEFAULT_SCHEDULER_PORT = 8786  # Dask's own default, for an address given without a port
LOCAL = "local"  # the client value (and ``--dask`` without an address) that starts a LocalCluster
WORKERS_RENAMED = ("{what}(workers=) was the number of Dask processes of a 'local' cluster: "
                   "it is now processes= ('workers' means CPU threads everywhere in warpsim; a "
                   "shard's threads are threads=)")
"""The error for the keyword ``workers`` of :func:`~warpsim.distributed.run` and
:func:`~warpsim.distributed.sweep`, which counted processes before it was renamed."""
DASK_MISSING = 'dask is needed for distributed runs: pip install "warpsim[dask]"'


def require_dask():
    """Import ``distributed``; a missing one is a one-line ImportError naming the extra."""
    try:
        import distributed
    except ImportError:
        raise ImportError(DASK_MISSING) from None
    return distributed


def scheduler_address(text: str) -> str:
    """A scheduler address in Dask's form (``tcp://HOST:PORT``), checked.

    Accepts ``HOST:PORT``, ``HOST`` (port 8786, Dask's default) and ``SCHEME://HOST:PORT`` for
    the schemes Dask knows (``tcp``, ``tls``, ``inproc``, ``ucx``, ``ws``, ``wss``).

    Raises:
        ValueError: not a string, empty, an unknown scheme, no host, or a bad port.
    """
    if not isinstance(text, str) or not text.strip():
        raise ValueError(f"Dask scheduler address must be HOST:PORT or tcp://HOST:PORT, got "
                         f"{text!r}")
    raw = text.strip()
    scheme, sep, rest = raw.partition("://")
    if not sep:
        scheme, rest = "tcp", raw
    known = ("tcp", "tls", "inproc", "ucx", "ws", "wss")
    if scheme not in known:
        raise ValueError(f"Dask scheduler address {text!r}: unknown scheme {scheme!r} (use one "
                         f"of {', '.join(known)})")
    if scheme == "inproc":
        if not rest:
            raise ValueError(f"Dask scheduler address {text!r} has no location")
        return raw
    host, colon, port = rest.rpartition(":")
    if not colon:
        host, port = rest, str(DEFAULT_SCHEDULER_PORT)
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    if not host or "/" in host or any(c.isspace() for c in host):
        raise ValueError(f"Dask scheduler address {text!r} has no valid host (expected "
                         f"HOST:PORT or tcp://HOST:PORT)")
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"Dask scheduler address {text!r}: port must be an integer in "
                         f"1..65535, got {port!r}")
    shown = f"[{host}]" if ":" in host else host
    return f"{scheme}://{shown}:{int(port)}"


@contextlib.contextmanager
def client_for(client, processes: int | None, timeout: float):
    """Yield a connected ``distributed.Client`` for ``client`` (LOCAL, an address or a Client);
    what this opened is closed on exit. ``processes``: the Dask worker processes (one thread
    each) of a LOCAL cluster (None: Dask's default, one per core)."""
    distributed = require_dask()
    if isinstance(client, distributed.Client):
        yield client
        return
    if client == LOCAL:
        if processes is not None:
            check.positive_int("processes", processes)
        with distributed.LocalCluster(n_workers=processes, threads_per_worker=1, processes=True,
                                      dashboard_address=None) as cluster, \
                distributed.Client(cluster) as local:
            yield local
        return
    if not isinstance(client, str):
        raise ValueError(f"client must be None, {LOCAL!r}, a scheduler address or a "
                         f"distributed.Client, got {type(client).__name__}")
    address = scheduler_address(client)
    try:
        remote = distributed.Client(address, timeout=timeout)
    except (OSError, TimeoutError) as exc:
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise OSError(f"no Dask scheduler answered at {address} within {timeout:g} s "
                      f"({reason})") from None
    try:
        yield remote
    finally:
        remote.close()


def cluster_threads(client) -> tuple[int, int]:
    """(processes, threads) of the cluster now: its Dask workers and their threads in all."""
    processes = client.scheduler_info().get("workers", {})
    return len(processes), sum(int(w.get("nthreads", 1)) for w in processes.values())
