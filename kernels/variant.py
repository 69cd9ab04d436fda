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


def variant_kernel(function):
    """``@wp.kernel`` for one variant: a module of its own, no backward pass.

    Use it where a factory defines its kernel, in place of ``@wp.kernel(module="unique")``.
    """
    return wp.kernel(function, module="unique", module_options=dict(KERNEL_OPTIONS),
                     **KERNEL_OPTIONS)
