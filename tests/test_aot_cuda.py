"""Every kernel factory compiles for NVIDIA GPUs ahead of time, without a GPU.

Warp generates CUDA code for a module and NVRTC (shipped with Warp) compiles it to PTX for a
chosen architecture (``wp.compile_aot_module(module, arch=..., use_ptx=True)``), so a kernel
that would fail to build on a GPU fails here on the CPU-only machine first. Checked for sm_80
(A100) and sm_90 (H100/H200):

- in the suite (slow tier, about two minutes here): a sample of 16 kernels, each for one of
  the two architectures: the frame kernel with every optional feature on (the most code) with
  the grid-then-BVH broad phase and with the walked grid (``walk-bvh``), and the collide and
  bounce kernels with the grid-then-BVH broad phase and every feature on, each in both
  precisions and motions. Each architecture gets every factory, precision and motion, in
  turns (:func:`sample`), so the suite pays for each kernel once, not once per architecture;
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
    """(label, kernel) of the sample the suite checks for ``arch``: of the 16 kernels (four
    kinds, each in both precisions and motions), those whose kind and precision-motion pair
    take this architecture in turns; each architecture gets every kind twice and every pair
    twice, and the two together get all 16."""
    out = []
    for j, (p, m) in enumerate(itertools.product(PRECISIONS, MOTIONS)):
        f = Features(precision=p, motion=m, broad_phase="grid-bvh")
        kinds = (
            (f"frame/{p}/{m}/grid-bvh/all-on", frame_kernel, f.but(**ALL_ON)),
            (f"collide/{p}/{m}/grid-bvh", collide_kernel, f),
            (f"bounce/{p}/{m}/grid-bvh/all-on", bounce_kernel, f.but(spin=True, lossy=True)),
            (f"frame/{p}/{m}/walk-bvh/all-on", frame_kernel,
             f.but(broad_phase="walk-bvh", **ALL_ON)),
        )
        for k, (label, factory, features) in enumerate(kinds):
            if ARCHS[(j + k) % len(ARCHS)] == arch:
                out.append((label, factory(features)))
    return out


def test_the_sample_gives_each_architecture_every_kind_and_all_of_it_together():
    labels = {arch: [label for label, _ in sample(arch)] for arch in ARCHS}
    for arch in ARCHS:
        assert len(labels[arch]) == 8
        assert {label.split("/")[0] for label in labels[arch]} == {"frame", "collide", "bounce"}
        assert {tuple(label.split("/")[1:3]) for label in labels[arch]} == set(
            itertools.product(PRECISIONS, MOTIONS))
    assert len(set(labels[80]) | set(labels[90])) == 16


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


def compiles(kernel, arch, folder) -> None:
    paths = wp.compile_aot_module(kernel.module, arch=arch, module_dir=folder, use_ptx=True)
    assert paths and all(p.suffix == ".ptx" and p.stat().st_size > 0 for p in paths)
    assert all(f"sm{arch}" in p.name for p in paths)


CHOICES = {"sample": sample, "factories": per_factory,
           "all": lambda arch: every_kernel_variant()}


@pytest.mark.slow
@pytest.mark.parametrize("arch", ARCHS)
def test_kernels_compile_for_the_gpu(arch, tmp_path):
    choice = os.environ.get("WARPSIM_AOT", "sample")
    if choice not in CHOICES:
        pytest.fail(f"WARPSIM_AOT must be one of {sorted(CHOICES)}, got {choice!r}")
    kernels = CHOICES[choice](arch)
    failed = []
    for label, kernel in kernels:
        try:
            compiles(kernel, arch, tmp_path)
        except Exception as exc:  # noqa: BLE001 - collect every failing variant, then report
            failed.append(f"{label}: {str(exc).splitlines()[0] if str(exc) else type(exc)}")
    assert not failed, f"{len(failed)} of {len(kernels)} kernels failed for sm_{arch}: {failed}"
