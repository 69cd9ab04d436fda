"""``python -m benchmarks.peers``: see :mod:`benchmarks.peers.run`."""

import os

# one core per engine: NumPy's BLAS (and anything else that reads these) single-threaded
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import sys  # noqa: E402

from .run import main  # noqa: E402

sys.exit(main())
