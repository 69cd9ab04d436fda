"""``benchmarks.store_forwarding``: the scan lists a stack load exactly when the youngest store
it overlaps, on the fall-through path and within the window, does not hold all its bytes; and
on a real kernel it reads the forward function and places what it lists on kernel
statements."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from benchmarks import store_forwarding as sf

ROOT = Path(__file__).resolve().parents[1]


def code(*lines: str) -> list[tuple[int, str, str]]:
    """``(offset, mnemonic, operands)`` rows, one per ``"mnemonic operands"``, 4 bytes apart."""
    out = []
    for i, line in enumerate(lines):
        mnemonic, _, operands = line.partition(" ")
        out.append((0x100 + 4 * i, mnemonic, operands.strip()))
    return out


def listed(*lines: str, window: int = sf.WINDOW) -> list[int]:
    return sorted(sf.split_store_loads(code(*lines), window))


@pytest.mark.parametrize("mnemonic, operands, size", [
    ("mov", "0x118(%rsp),%r8d", 4), ("mov", "%r12d,0x820(%rsp)", 4),
    ("mov", "0x730(%rsp),%rdi", 8), ("mov", "%rax,0x10(%rsp)", 8),
    ("mov", "%eax,0x10(%rsp)", 4), ("mov", "%ax,0x10(%rsp)", 2), ("mov", "%al,0x10(%rsp)", 1),
    ("mov", "%r9w,0x10(%rsp)", 2), ("mov", "%r9b,0x10(%rsp)", 1),
    ("movl", "$0x1,0x820(%rsp)", 4), ("movq", "$0x0,0x824(%rsp)", 8),
    ("vmovss", "%xmm2,0x838(%rsp)", 4), ("vmovsd", "0x838(%rsp),%xmm9", 8),
    ("vmovlps", "%xmm0,0x81c(%rsp)", 8), ("vmovups", "%ymm0,0x1c(%rsp)", 32),
    ("vmovaps", "0x60(%rsp),%xmm1", 16), ("vmovupd", "0x248(%rsp),%xmm3", 16),
    ("vucomiss", "0x710(%rsp),%xmm0", 4), ("vsubps", "0x410(%rsp),%xmm1,%xmm1", 16),
    ("vaddsd", "0x8(%rsp),%xmm1,%xmm1", 8), ("cmp", "%eax,0x10(%rsp)", None),
    # AVX-512, as Warp's -march=native emits it on a CPU with it
    ("vmovups", "%zmm0,0x40(%rsp)", 64), ("vpermi2pd", "0x28(%rsp),%zmm2,%zmm0", 64),
    ("vmovdqu64", "0x80(%rsp),%zmm3", 64), ("vmovdqa32", "%ymm1,0x20(%rsp)", 32),
    ("vaddps", "0x10(%rsp){1to16},%zmm1,%zmm0", 4), ("vmulpd", "0x8(%rsp){1to8},%zmm1,%zmm0", 8),
])
def test_access_sizes(mnemonic, operands, size):
    assert sf.access_bytes(mnemonic, operands) == size


def test_a_load_across_two_stores_is_listed():
    """The forced BVH's query before the fix: its upper bound written a component at a time,
    two components read at once."""
    found = listed("vmovss %xmm2,0x838(%rsp)", "vmovss %xmm3,0x83c(%rsp)",
                   "vmovsd 0x838(%rsp),%xmm9")
    assert found == [0x108]
    record = sf.split_store_loads(code("vmovss %xmm2,0x838(%rsp)", "vmovss %xmm3,0x83c(%rsp)",
                                       "vmovsd 0x838(%rsp),%xmm9"))[0x108]
    assert record["load"].startswith("108: vmovsd")
    assert [s.split(":")[0] for s in record["stores"]] == ["100", "104"]


@pytest.mark.parametrize("lines", [
    # one store holds the load: the same bytes, or the load inside a wider store
    ("vmovlps %xmm2,0x828(%rsp)", "vmovsd 0x828(%rsp),%xmm7"),
    ("vmovups %xmm0,0x20(%rsp)", "vmovss 0x24(%rsp),%xmm1", "vmovsd 0x28(%rsp),%xmm2"),
    ("movl $0x0,0x118(%rsp)", "mov 0x118(%rsp),%r8d"),
    # the youngest overlapping store holds it, whatever older ones did
    ("vmovss %xmm2,0x838(%rsp)", "vmovss %xmm3,0x83c(%rsp)", "vmovlps %xmm4,0x838(%rsp)",
     "vmovsd 0x838(%rsp),%xmm9"),
    # no store overlaps, or the other base register's slot
    ("vmovss %xmm2,0x838(%rsp)", "vmovsd 0x840(%rsp),%xmm9"),
    ("vmovss %xmm2,0x38(%rbp)", "vmovss %xmm3,0x3c(%rbp)", "vmovsd 0x38(%rsp),%xmm9"),
    # an unconditional jump, a call, a return or a change of the stack pointer between
    ("vmovss %xmm2,0x38(%rsp)", "vmovss %xmm3,0x3c(%rsp)", "jmp 200 <f+0x10>",
     "vmovsd 0x38(%rsp),%xmm9"),
    ("vmovss %xmm2,0x38(%rsp)", "vmovss %xmm3,0x3c(%rsp)", "call *0x840(%rsp)",
     "vmovsd 0x38(%rsp),%xmm9"),
    ("vmovss %xmm2,0x38(%rsp)", "vmovss %xmm3,0x3c(%rsp)", "add $0x2a0,%rsp",
     "vmovsd 0x38(%rsp),%xmm9"),
])
def test_loads_that_one_store_feeds_or_none_are_not_listed(lines):
    assert listed(*lines) == []


def test_a_conditional_jump_keeps_the_fall_through_path():
    assert listed("vmovss %xmm2,0x38(%rsp)", "vmovss %xmm3,0x3c(%rsp)", "jne 200 <f+0x10>",
                  "vmovsd 0x38(%rsp),%xmm9") == [0x10c]


def test_stores_older_than_the_window_are_forgotten():
    lines = ["vmovss %xmm2,0x38(%rsp)", "vmovss %xmm3,0x3c(%rsp)",
             *["vaddss %xmm1,%xmm1,%xmm1"] * 10, "vmovsd 0x38(%rsp),%xmm9"]
    assert listed(*lines, window=20) == [0x100 + 4 * 12]
    assert listed(*lines, window=10) == []


@pytest.mark.skipif(any(shutil.which(t) is None for t in ("objdump", "addr2line", "nm")),
                    reason="binutils is not installed")
def test_a_real_kernel_is_read_and_its_loads_placed(tmp_path):
    """The study on the room's float64 ballistic kernel, in its own process (the kernel built
    with line tables there): every load it lists is placed on a statement of a kernel file,
    and the counts per statement add up to the kernel's."""
    out = tmp_path / "sf.json"
    subprocess.run([sys.executable, "-m", "benchmarks.store_forwarding", "--cases",
                    "float64/ballistic", "--out", str(out)], check=True, cwd=ROOT,
                   capture_output=True, timeout=600)
    result = json.loads(out.read_text(encoding="utf-8"))
    (row,) = result["rows"]
    assert (row["precision"], row["motion"]) == ("float64", "ballistic")
    assert sum(r["loads"] for r in result["loads"]) == row["loads"]
    assert len(result["loads"]) == row["statements"]
    for r in result["loads"]:
        assert r["file"].endswith(".py") and r["line"] > 0
        assert r["examples"] and all(e["load"] and e["stores"] for e in r["examples"])


def test_the_forward_function_is_read_from_its_symbol_on(tmp_path):
    """:func:`forward_disassembly` on an object built here: its first instruction is at the
    ``*_cpu_forward`` symbol (``frame_profile.forward_offset``)."""
    if any(shutil.which(t) is None for t in ("objdump", "nm")):
        pytest.skip("binutils is not installed")
    from benchmarks.frame_profile import forward_offset

    obj, _ = sf.build_case("room", "float32", "linear", "auto")
    disassembly = sf.forward_disassembly(obj)
    assert len(disassembly) > 1000
    assert disassembly[0][0] == forward_offset(obj)
    assert set(sf.split_store_loads(disassembly)) <= {o for o, _, _ in disassembly}
