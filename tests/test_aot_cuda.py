"""Every kernel factory compiles for NVIDIA GPUs ahead of time, without a GPU.

Warp generates CUDA code for a module and NVRTC (shipped with Warp) compiles it to PTX for a
chosen architecture (``wp.compile_aot_module(module, arch=..., use_ptx=True)``), so a kernel
that would fail to build on a GPU fails here on the CPU-only machine first. Checked for sm_80
(A100) and sm_90 (H100/H200):

- in the suite (slow tier): a sample of 8 kernels, four for each architecture, one of each
  kind: the frame kernel with every optional feature on (the most code) with the
  grid-then-BVH broad phase and with the walked grid (``walk-bvh``), the collide kernel with
  the BVH as its broad phase (its loop over the boxes kept out of the tree, gathered in
  float32), and the bounce kernel with the grid-then-BVH broad phase and every feature on.
  Each architecture gets every kind and every precision-motion pair once, and each kind
  gets both precisions and both motions over the two (:func:`sample`). The PTX goes to
  Warp's kernel cache, keyed by the module's content: a kernel already compiled for an
  architecture is not compiled again;
- ``WARPSIM_AOT=factories``: each factory over precision x motion x broad phase, with every
  feature on and, for the frame kernel, also with every one off;
- ``WARPSIM_AOT=all``: the whole product of every flag of every factory (about 300 kernels).
"""

import itertools
import os

import pytest
import warp as wp
from helpers import every_kernel_variant

from warpsim.kernels.collide_kernels import bounce_kernel, collide_kernel
from warpsim.kernels.data import BROAD_PHASES, MOTIONS, PRECISIONS, Features
from warpsim.kernels.frame_kernel import frame_kernel

ARCHS = (80, 90)
ALL_ON = dict(spin=True, lossy=True, energy_correction=True, events=True, births=True,
              falls=True)
ALL_OFF = dict(spin=False, lossy=False, energy_correction=False, events=False, births=False,
               falls=False)


def sample(arch: int):
    """(label, kernel) of the sample the suite checks for ``arch``: kind ``k`` of the four
    takes precision-motion pair ``k`` for sm_80 and pair ``3 - k`` for sm_90 (pairs in the
    order of ``PRECISIONS x MOTIONS``), so each architecture gets every kind and every pair
    once, and each kind one pair of either precision and either motion."""
    pairs = list(itertools.product(PRECISIONS, MOTIONS))
    out = []
    for k in range(4):
        p, m = pairs[k if arch == ARCHS[0] else 3 - k]
        f = Features(precision=p, motion=m, broad_phase="grid-bvh")
        label, factory, features = (
            (f"frame/{p}/{m}/grid-bvh/all-on", frame_kernel, f.but(**ALL_ON)),
            (f"collide/{p}/{m}/bvh", collide_kernel, f.but(broad_phase="bvh")),
            (f"bounce/{p}/{m}/grid-bvh/all-on", bounce_kernel, f.but(spin=True, lossy=True)),
            (f"frame/{p}/{m}/walk-bvh/all-on", frame_kernel,
             f.but(broad_phase="walk-bvh", **ALL_ON)),
        )[k]
        out.append((label, factory(features)))
    return out


def test_the_sample_gives_each_architecture_every_kind_and_pair_and_each_kind_both_of_each():
    labels = {arch: [label for label, _ in sample(arch)] for arch in ARCHS}
    for arch in ARCHS:
        assert len(labels[arch]) == 4
        assert {label.split("/")[0] for label in labels[arch]} == {"frame", "collide", "bounce"}
        assert {tuple(label.split("/")[1:3]) for label in labels[arch]} == set(
            itertools.product(PRECISIONS, MOTIONS))
    both = labels[80] + labels[90]
    assert len(set(both)) == 8
    for kind in ("frame/grid-bvh", "collide", "bounce", "frame/walk-bvh"):
        name, _, broad = kind.partition("/")
        pairs = [label.split("/")[1:3] for label in both
                 if label.startswith(name + "/") and (not broad or broad in label)]
        assert {p for p, _ in pairs} == set(PRECISIONS), kind
        assert {m for _, m in pairs} == set(MOTIONS), kind


def per_factory(arch: int):
    """(label, kernel) of every factory over precision x motion x broad phase, for either
    architecture."""
    out = []
    for p, m, b in itertools.product(PRECISIONS, MOTIONS, BROAD_PHASES):
        f = Features(precision=p, motion=m, broad_phase=b)
        out.append((f"collide/{p}/{m}/{b}", collide_kernel(f)))
        out.append((f"bounce/{p}/{m}/{b}/all-on", bounce_kernel(f.but(spin=True, lossy=True))))
        out.append((f"frame/{p}/{m}/{b}/all-on", frame_kernel(f.but(**ALL_ON))))
        out.append((f"frame/{p}/{m}/{b}/all-off", frame_kernel(f.but(**ALL_OFF))))
    return out


def compiles(kernel, arch, folder=None) -> None:
    """Compiles ``kernel``'s module to PTX for ``arch`` (into ``folder``; None: Warp's kernel
    cache, where a module already compiled for ``arch`` is not compiled again)."""
    paths = wp.compile_aot_module(kernel.module, arch=arch, module_dir=folder, use_ptx=True)
    assert paths and all(p.suffix == ".ptx" and p.stat().st_size > 0 for p in paths)
    assert all(f"sm{arch}" in p.name for p in paths)


CHOICES = {"sample": sample, "factories": per_factory,
           "all": lambda arch: every_kernel_variant()}


@pytest.mark.slow
@pytest.mark.parametrize("arch", ARCHS)
def test_kernels_compile_for_the_gpu(arch):
    choice = os.environ.get("WARPSIM_AOT", "sample")
    if choice not in CHOICES:
        pytest.fail(f"WARPSIM_AOT must be one of {sorted(CHOICES)}, got {choice!r}")
    kernels = CHOICES[choice](arch)
    failed = []
    for label, kernel in kernels:
        try:
            compiles(kernel, arch)
        except Exception as exc:  # noqa: BLE001 - collect every failing variant, then report
            failed.append(f"{label}: {str(exc).splitlines()[0] if str(exc) else type(exc)}")
    assert not failed, f"{len(failed)} of {len(kernels)} kernels failed for sm_{arch}: {failed}"
