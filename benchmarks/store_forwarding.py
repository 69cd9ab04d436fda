"""Loads that wait for stores: the frame kernel's stack loads that read bytes written by more
than one store (or by part of one) shortly before, on the same path through the code.

An x86 core hands a load its bytes from a store still in its store buffer only when one store
wrote all of them; a load that spans two stores (a vector written a component at a time and
read whole, or written whole and read across its end) waits until those stores reach the cache
(a store-forwarding failure; what it costs depends on the CPU and on what else is in flight,
and is not measured here). Clang makes such pairs where a vector goes through the stack: a
component written at a run-time index, a struct built field by field and copied whole, a value
passed by memory to an out-of-line function. The forced BVH's frame did one per query (its
bounds written a component at a time, read two at once), and building them as whole vectors
made it 0.91 to 0.94x; removing 1.2 such loads a sphere-frame from the float64 ballistic frame
showed no gain beyond the noise (BENCHMARKS.md, "Loads that wait for stores"). A listed load
is a place to look, not a cost.

The scan reads the kernel's disassembly (``objdump``, AT&T syntax), the ``*_cpu_forward``
function only, in the order it is laid out: a conditional jump's fall-through goes on with the
stores before it, an unconditional jump, a call, a return or a change of the stack pointer
forgets them. A load from ``disp(%rsp)`` or ``disp(%rbp)`` whose bytes overlap a store of
the last ``WINDOW`` instructions, where the youngest such store does not hold them all, is
listed. It sees only the stack (the kernel's other memory is its arrays) and only the
fall-through paths (a load reached by a jump from elsewhere may not wait), so it may miss
some and list some that wait on one path only; how often a listed load runs is what
``benchmarks.instructions --where`` counts (its ``split-store loads`` column).

Run from the repository root: ``python -m benchmarks.store_forwarding [--cases
float32/linear,...] [--broad-phase auto] [--scene room]``: builds each case's kernel with line
tables (``frame_profile``'s, which leave the code as it was) and lists its loads by the Python
statement they are in. Needs binutils (``objdump``, ``addr2line``, ``nm``).
"""

from __future__ import annotations

import collections
import inspect
import re
import subprocess
import sys
import time
from pathlib import Path

from .common import finish, parser, print_table, start
from .frame_profile import (
    LINE_TABLES,
    generated_statements,
    innermost_cpp_lines,
    statement_at,
)
from .hot_loop import CASES

#: Instructions back that a store still counts: about what a core keeps in flight (Zen 3
#: retires 256), so an older store has most likely reached the cache.
WINDOW = 96

#: Bytes moved by the moves whose size the mnemonic alone gives (others: by the register).
MOVE_BYTES = {"vmovss": 4, "movss": 4, "vmovd": 4, "movd": 4, "movl": 4, "vmovsd": 8,
              "movsd": 8, "vmovq": 8, "movq": 8, "vmovlps": 8, "vmovhps": 8, "vmovlpd": 8,
              "vmovhpd": 8, "movw": 2, "movb": 1, "vbroadcastss": 4, "vbroadcastsd": 8,
              "vmovddup": 8, "vinsertps": 4, "vextractps": 4}

#: Moves of a whole register (16 bytes with ``xmm``, 32 with ``ymm``).
VECTOR_MOVES = ("vmovups", "vmovaps", "vmovupd", "vmovapd", "vmovdqu", "vmovdqa", "vmovshdup",
                "vmovsldup", "vmovdqu32", "vmovdqu64", "vmovdqa32", "vmovdqa64")

#: An AVX-512 memory operand broadcast from one element (``(%rsp){1to16}``): its element's
#: bytes are read, not the register's.
BROADCAST = re.compile(r"\{1to\d+\}")

INSTRUCTION = re.compile(r"^\s*([0-9a-f]+):\s+(\S+)\s*(.*)$")
STACK = re.compile(r"(?<![\w)])(-?0x[0-9a-f]+|-?\d+)?\((%rsp|%rbp)\)")
GENERAL = re.compile(r"%([a-z][a-z0-9]*)")


def access_bytes(mnemonic: str, operands: str) -> int | None:
    """The bytes a move (or a scalar or packed arithmetic with a memory operand) reads or
    writes; None when not known."""
    if mnemonic in MOVE_BYTES:
        return MOVE_BYTES[mnemonic]
    if BROADCAST.search(operands):
        return 8 if mnemonic.endswith(("pd", "q")) else 4
    # AVX-512 (a CPU with it, where Warp's -march=native uses it): 64-byte zmm registers
    wide = 64 if "%zmm" in operands else 32 if "%ymm" in operands else 16
    if mnemonic in VECTOR_MOVES or mnemonic.endswith(("ps", "pd")):
        return wide
    if mnemonic.endswith("ss"):
        return 4
    if mnemonic.endswith("sd"):
        return 8
    if mnemonic == "mov":
        reg = GENERAL.search(re.sub(r"\([^)]*\)", "", operands))  # not the address's
        if reg is None:
            return None
        name = reg.group(1)
        if name[0] == "e" or name.endswith("d"):
            return 4
        if name.endswith("w") or len(name) == 2 and name[1] in "xip":
            return 2
        if name.endswith(("b", "l")):
            return 1
        return 8
    return None


def forward_disassembly(obj: Path) -> list[tuple[int, str, str]]:
    """``(offset, mnemonic, operands)`` of each instruction of the object's ``*_cpu_forward``
    function, offsets as ``objdump`` gives them (the section's)."""
    text = subprocess.run(["objdump", "-d", "--no-show-raw-insn", str(obj)],
                          capture_output=True, text=True, check=True).stdout
    out, inside = [], False
    for line in text.splitlines():
        if line.endswith("_cpu_forward>:"):
            inside = True
            continue
        if inside:
            if not line.strip():
                break
            m = INSTRUCTION.match(line)
            if m:
                out.append((int(m.group(1), 16), m.group(2), m.group(3).split("#")[0].strip()))
    return out


def split_store_loads(code: list[tuple[int, str, str]], window: int = WINDOW) -> dict[int, dict]:
    """``{offset: {"load": text, "stores": [text, ...]}}``: each stack load of ``code`` (as
    :func:`forward_disassembly` gives it) that overlaps an earlier store on its fall-through
    path (a conditional jump keeps the stores before it; an unconditional jump, a call, a
    return or a change of the stack pointer forgets them), within ``window`` instructions,
    where the youngest overlapping store does not hold all its bytes (the stores listed are
    the overlapping ones, oldest first, the last four)."""
    found: dict[int, dict] = {}
    stores: list[tuple[int, int, int, str, str]] = []  # (index, start, size, base, text)
    for index, (offset, mnemonic, operands) in enumerate(code):
        text = f"{offset:x}: {mnemonic} {operands}"
        if mnemonic.startswith("j"):  # a taken jump leaves the run; the next one starts anew
            if mnemonic == "jmp":
                stores = []
            continue
        if (mnemonic.startswith(("call", "ret", "push", "pop", "leave"))
                or operands.endswith(",%rsp")):
            stores = []
            continue
        m = STACK.search(operands)
        if m is None:
            continue
        size = access_bytes(mnemonic, operands)
        if size is None:
            continue
        start = int(m.group(1), 0) if m.group(1) else 0
        base = m.group(2)
        if STACK.search(operands.rsplit(",", 1)[-1]) and "," in operands:  # the destination
            stores.append((index, start, size, base, text))
            continue
        overlapping = [s for s in stores if s[3] == base and index - s[0] <= window
                       and s[1] < start + size and start < s[1] + s[2]]
        if overlapping:
            _, s_start, s_size, _, _ = overlapping[-1]
            if not (s_start <= start and start + size <= s_start + s_size):
                found[offset] = {"load": text, "stores": [s[4] for s in overlapping[-4:]]}
    return found


def statements_of(obj: Path, offsets: list[int], kernel_file: str) -> dict[int, tuple]:
    """``{offset: (file, line, text)}``: the Python statement each offset's code is in (the
    object's line tables, then the generated C++'s statement comments)."""
    lines = innermost_cpp_lines(obj, sorted(offsets))
    cpp = next(obj.parent.glob("*.cpp")).read_text(encoding="utf-8")
    statements = generated_statements(cpp, kernel_file)
    out = {}
    for offset in offsets:
        line = lines.get(offset)
        s = statement_at(statements, line) if line is not None else None
        out[offset] = (Path(s.file).name, s.line, s.text) if s else ("?", 0, "(no line)")
    return out


def build_case(scene_name: str, prec: str, motion: str, broad_phase: str) -> tuple[Path, str]:
    """Builds the case's frame kernel (this process's Warp, with line tables) and returns its
    object file and the kernel's source file."""
    import warp as wp

    import warpsim as ws

    scene = ws.Scene.load(scene_name)
    sim = ws.Simulator(scene, scene.spawn(n=64, seed=0), precision=prec, motion=motion,
                       workers=1, device="cpu", broad_phase=broad_phase)
    sim.build()
    kernel = sim._kernel
    exe = next(iter(kernel.module.execs.values()))
    wp.synchronize_device("cpu")
    return Path(exe.binary_path), inspect.getsourcefile(kernel.func)


def main(argv=None) -> None:
    p = parser("store_forwarding", __doc__)
    p.add_argument("--scene", default="room", help="bundled scene (default room)")
    p.add_argument("--cases", default=None,
                   help="comma-separated PRECISION/MOTION pairs (default: all four)")
    p.add_argument("--broad-phase", default="auto",
                   help="the simulators' broad_phase (default auto; bvh, brute, grid, walk)")
    args = p.parse_args(argv)
    if args.device != "cpu":
        sys.exit("benchmarks.store_forwarding reads the CPU kernel: --device must be cpu")
    import warp as wp

    wp.config.cpu_compiler_flags = (wp.config.cpu_compiler_flags or "") + LINE_TABLES
    cases = CASES if args.cases is None else [tuple(c.split("/")) for c in args.cases.split(",")]
    started = time.perf_counter()
    _, info, out = start("store_forwarding", args)
    rows, loads = [], []
    for prec, motion in cases:
        obj, kernel_file = build_case(args.scene, prec, motion, args.broad_phase)
        found = split_store_loads(forward_disassembly(obj))
        where = statements_of(obj, list(found), kernel_file)
        by = collections.Counter(where.values())
        rows.append({"precision": prec, "motion": motion, "broad_phase": args.broad_phase,
                     "loads": len(found), "statements": len(by)})
        for (file, line, text), count in by.most_common():
            loads.append({"precision": prec, "motion": motion, "loads": count, "file": file,
                          "line": line, "text": text,
                          "examples": [found[o] for o in found if where[o] == (file, line,
                                                                                text)][:2]})
    print_table(f"Stack loads that span stores, scene {args.scene}, per kernel", rows,
                [("precision", "precision", "s"), ("motion", "motion", "s"),
                 ("broad phase", "broad_phase", "s"), ("loads", "loads", ""),
                 ("statements", "statements", "")])
    print_table("Where they are", loads,
                [("precision", "precision", "s"), ("motion", "motion", "s"),
                 ("loads", "loads", ""), ("file", "file", "s"), ("line", "line", ""),
                 ("statement", "text", "s")])
    finish(out, {"machine": info, "scene": args.scene, "broad_phase": args.broad_phase,
                 "rows": rows, "loads": loads}, started)


if __name__ == "__main__":
    main()
