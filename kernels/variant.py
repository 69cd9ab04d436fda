"""How every kernel of this package is made: one decorator, so no variant carries adjoint code.

``@wp.kernel(module="unique")`` gives each kernel variant a fresh module with Warp's *default*
options, so a ``wp.set_module_options({"enable_backward": False})`` at the top of a file never
reaches it and Warp generates and compiles the adjoint (reverse-mode) code of every function the
kernel calls. Nothing here is differentiated, and that code doubled the cold build time of a
frame-kernel variant (10.8 s against 5.2 s). :func:`variant_kernel` turns it off on the kernel
and on its module.
"""

import warp as wp

#: The options every kernel of this package is built with (checked by the tests).
KERNEL_OPTIONS = {"enable_backward": False}

#: The compiler's optimisation level of every module of this package (the module option
#: ``optimization_level``; Warp's own default is 3 for a GPU and 2 for the CPU). On an H200 the
#: ballistic frame kernel built in 246 s at level 3 and in 2.9 s at level 2, and ran at the
#: same speed with the same bits (``benchmarks/results/opt_level-cuda.json``); on the CPU the
#: level was already 2.
OPTIMIZATION_LEVEL = 2


def variant_kernel(function):
    """``@wp.kernel`` for one variant: a module of its own, no backward pass.

    Use it where a factory defines its kernel, in place of ``@wp.kernel(module="unique")``.
    """
    return wp.kernel(function, module="unique",
                     module_options={**KERNEL_OPTIONS, "optimization_level": OPTIMIZATION_LEVEL},
                     **KERNEL_OPTIONS)
