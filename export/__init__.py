"""USD export of warpsim results; imported only when used, so ``import warpsim`` never needs pxr.

Import it as ``warpsim.export``.
"""

if __name__ != "warpsim.export":  # imported as a bare ``export``: the package would load twice
    raise ImportError("import this package as 'warpsim.export', not as 'export'")
