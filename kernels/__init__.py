"""Warp code of warpsim: ``@wp.func`` geometry and the ``@wp.kernel`` factories that compose it.

Import it as ``warpsim.kernels``. Nothing here uses numpy or does I/O.
"""

if __name__ != "warpsim.kernels":  # imported as a bare ``kernels``: Warp would build it twice
    raise ImportError("import this package as 'warpsim.kernels', not as 'kernels'")
