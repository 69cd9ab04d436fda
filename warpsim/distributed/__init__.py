"""The same run on a Dask cluster, by job: the sharded draw (:mod:`.draw`), the sharded run and
its USD layers (:mod:`.shards`), a generic sweep of tasks (:mod:`.sweeps`), and the Dask clients
both use (:mod:`.cluster`). Dask is an optional extra (``warpsim[dask]``), imported only when a
cluster is asked for.
"""

from .cluster import LOCAL, require_dask, scheduler_address
from .draw import (
           DEFAULT_BLOCK,
           block_count,
           block_seed,
           plan_shards,
           shard_swarm,
           sharded_spawn,
           spawn_block,
)
from .shards import RunSpec, RunSummary, read, run, scene_key, simulate_shard
from .sweeps import sweep

__all__ = ["DEFAULT_BLOCK", "LOCAL", "RunSpec", "RunSummary", "block_count", "block_seed",
           "plan_shards", "read", "require_dask", "run", "scene_key", "scheduler_address",
           "shard_swarm", "sharded_spawn", "simulate_shard", "spawn_block", "sweep"]
