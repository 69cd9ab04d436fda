"""warpsim beside the engines users would pick instead: one workload, one driver per engine.

Run ``python -m benchmarks.peers`` from the repository root (``--help`` for the options) after
``pip install -e ".[peers]"``; engines that are not installed are left out of the table and
said so. See the section "Against other engines" of BENCHMARKS.md.

Modules:

- :mod:`benchmarks.peers.workload`: the room, the plates, the spheres and the measures, the same
  for every engine.
- ``*_driver.py``: one engine each (warpsim, a NumPy discrete baseline, PyBullet, MuJoCo,
  Newton), each with the same small interface (:class:`benchmarks.peers.workload.Driver`) and a
  docstring that says how faithfully the engine can be set up for the workload.
- :mod:`benchmarks.peers.run`: runs them all, interleaved and repeated, and writes the table
  (Markdown and JSON) and the plot.
"""
