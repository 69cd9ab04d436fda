"""Studies behind BENCHMARKS.md: scripts run from the repository root, not part of the package.

- ``python -m benchmarks.broad_walk [--quick]``: the walked grid against the other broad phases
  and main's ``auto`` as spheres get faster (the standard room, thin walls, plates).
- ``python -m benchmarks.sweep [--quick]``: the sweep kernel against ``warpsim.collide_boxes``
  and the NumPy baseline (:mod:`benchmarks.numpy_sweep`); brute force against the BVH.
- ``python -m benchmarks.speed [--quick]``: the simulator's ns per sphere-frame in the standard
  room per broad phase, launch mode, speed and precision; cost against the box count; workers.
- ``python -m benchmarks.accuracy_tables [--quick]``: float32 against float64, error against
  step size, long-run energy drift.
- ``python -m benchmarks.build_times [--quick]``: the cold build time of each kernel variant.
- ``python -m benchmarks.ballistic [--quick]``: the ballistic model against the exact reference,
  its energy drift and its cost against the linear model.
- ``python -m benchmarks.peers``: warpsim against other engines (see ``benchmarks/peers``).
- ``python -m benchmarks.usd_write``, ``python -m benchmarks.dask_scaling``: USD writing time,
  and sphere-frames per second against Dask workers.

Each prints markdown tables and writes its JSON under ``benchmarks/results/`` (with the
machine and the git commit, :func:`warpsim.machine.machine`).
"""
