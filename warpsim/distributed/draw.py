"""The sharded draw: the spheres of a swarm drawn block by block, so that any shard draws its
own spheres without the rest.

Sphere ``i`` of a swarm of ``n`` belongs to block ``i // block``; block ``b``
is the emitter's draw ``scene.spawn(n=size_b, seed=block_seed(seed, b))`` (``size_b`` is
``block`` but for a shorter last block). A shard is a run of whole blocks, so any shard draws the
same spheres as a one-process run of the whole swarm: :func:`sharded_spawn` (all blocks) and
:func:`shard_swarm` (some blocks) are the one draw both paths use, and the composed result is
bit-identical whatever the number of Dask processes or shards. Every block is checked clear of the
obstacles, per sphere (the emitter's rejection sampling, then
:func:`warpsim.feasibility.check_outside`), exactly as :meth:`warpsim.Scene.spawn` checks it.
It is **not** the draw of ``scene.spawn(n, seed)`` (one stream for the whole swarm): a single
stream cannot be split among processes without drawing all of it, so the sharded draw is its own
(equally valid) sample; ``warpsim run`` uses it with or without ``--dask``/``--shards``, so the
same command always simulates the same spheres. Changing
``block`` changes the draw; it is stored in every manifest.
"""

from __future__ import annotations

import functools

import numpy as np

from .. import validation as check
from ..scene import Scene
from ..swarm import FIELDS, Swarm

DEFAULT_BLOCK = 1024
"""Spheres per block of the sharded draw. Measured on the room scene: drawing a block costs
about 5 ms of fixed overhead plus 5 us per sphere, so 1024-sphere blocks keep the draw within
7 us per sphere (a 300-frame run costs about 45 us per sphere) while a shard can still be as
small as one block."""

SEED_LIMIT = 1 << 31  # emitter seeds are integers below 2**31
_BLOCK_TAG = 0x5751_4B42  # domain separation of the block-seed keys from other uses of a seed


def _feistel_round(half: int, key: int) -> int:
    h = (half * 0x9E3779B1 + key) & 0xFFFFFFFF
    h ^= h >> 15
    h = (h * 0x85EBCA6B) & 0xFFFFFFFF
    h ^= h >> 13
    return h & 0xFFFF


@functools.lru_cache(maxsize=64)
def _block_keys(seed: int) -> tuple[int, ...]:
    """The four round keys of a seed's block permutation."""
    return tuple(int(k) for k in np.random.SeedSequence([_BLOCK_TAG, seed]).generate_state(4))


def block_seed(seed: int, block: int) -> int:
    """The emitter seed of block ``block`` of the sharded draw with seed ``seed``.

    A keyed permutation of ``[0, 2**31)`` (a four-round Feistel network on 32 bits, cycle-walked
    into 31 bits, keyed by ``numpy.random.SeedSequence`` of the seed): the blocks of one run
    always get distinct seeds (so distinct streams), and the block seeds of two different run
    seeds are unrelated.

    Args:
        seed: the run's seed, an integer >= 0.
        block: the block number, in ``[0, 2**31)``.

    Returns:
        An integer in ``[0, 2**31)``.
    """
    seed = check.positive_int("seed", seed, minimum=0)
    block = check.positive_int("block", block, minimum=0)
    keys = _block_keys(seed)
    x = block
    while True:  # cycle walking: a permutation of [0, 2**32) restricted to [0, 2**31)
        left, right = x >> 16, x & 0xFFFF
        for key in keys:
            left, right = right, left ^ _feistel_round(right, key)
        x = (left << 16) | right
        if x < SEED_LIMIT:
            return x


def check_draw(scene: Scene, n, seed, block) -> tuple[int, int, int]:
    """Validated ``(n, seed, block)`` of the scene's sharded draw (n=None: the emitter's count,
    seed=None: the emitter's seed)."""
    if not isinstance(scene, Scene):
        raise ValueError(f"scene must be a warpsim.Scene, got {type(scene).__name__}")
    if scene.emitter is None:
        raise ValueError(f"scene {scene.name!r} has no emitter: a sharded run draws its spheres "
                         f"from the scene's emitter")
    n = scene.emitter.count if n is None else check.positive_int("n", n)
    seed = scene.emitter.seed if seed is None else check.positive_int("seed", seed, minimum=0)
    block = check.positive_int("block", block)
    return n, seed, block


def block_count(n: int, block: int = DEFAULT_BLOCK) -> int:
    """Blocks of a swarm of ``n`` spheres: ``ceil(n / block)``."""
    return -(-n // block)


def spawn_block(scene: Scene, n: int | None, seed: int | None, index: int,
                block: int = DEFAULT_BLOCK, dt: float | None = None) -> Swarm:
    """Spheres ``index * block`` to ``min((index + 1) * block, n)`` of the sharded draw.

    Args:
        scene: a scene with an emitter and obstacles.
        n: spheres of the whole swarm (None: the emitter's count).
        seed: the run's seed (None: the emitter's).
        index: the block number, in ``[0, ceil(n / block))``.
        block: spheres per block.
        dt: the run's frame duration [s] (None: the scene's), that an emitter emitting over
            time counts its birth frames in: those of the block's spheres in the whole swarm.

    Returns:
        The block's spheres, each clear of every obstacle.

    Raises:
        ValueError: bad arguments (named), or the emitter cannot place the block.
    """
    n, seed, block = check_draw(scene, n, seed, block)
    blocks = block_count(n, block)
    index = check.positive_int("index", index, minimum=0, maximum=blocks - 1,
                               reason=f"{n} spheres make {blocks} blocks of {block}")
    size = min(block, n - index * block)
    dt = scene.dt if dt is None else dt
    swarm = scene.spawn(n=size, seed=block_seed(seed, index), dt=dt)
    if not getattr(scene.emitter, "emits_over_time", False):
        return swarm
    return _with(swarm,
                 birth_frame=scene.emitter.birth_frames(dt, n, index * block, size))


def shard_swarm(scene: Scene, n: int | None, seed: int | None, start: int, stop: int,
                block: int = DEFAULT_BLOCK, dt: float | None = None) -> Swarm:
    """Spheres ``start`` to ``stop`` (excluded) of the sharded draw, made of whole blocks.

    Args:
        start: a multiple of ``block``; stop: a multiple of ``block`` or ``n``, > ``start``.

    Raises:
        ValueError: a range that is not whole blocks, or out of ``[0, n]``.
    """
    n, seed, block = check_draw(scene, n, seed, block)
    start = check.positive_int("start", start, minimum=0, maximum=n - 1)
    stop = check.positive_int("stop", stop, minimum=start + 1, maximum=n)
    if start % block or (stop % block and stop != n):
        raise ValueError(f"spheres {start}..{stop} are not whole blocks of {block} (a shard "
                         f"starts and ends on a multiple of block, or ends at n = {n})")
    # the blocks drawn together (each as spawn_block draws it, bit for bit)
    dt = scene.dt if dt is None else dt
    blocks = range(start // block, block_count(stop, block))
    sizes = [min(block, n - b * block) for b in blocks]
    (swarm,) = scene.spawn_many(sizes, [block_seed(seed, b) for b in blocks], dt=dt, join=True)
    if getattr(scene.emitter, "emits_over_time", False):  # births counted in the whole swarm
        swarm = _with(swarm, birth_frame=np.concatenate(
            [scene.emitter.birth_frames(dt, n, b * block, size)
             for b, size in zip(blocks, sizes, strict=True)]))
    return swarm


def sharded_spawn(scene: Scene, n: int | None = None, seed: int | None = None,
                  block: int = DEFAULT_BLOCK, dt: float | None = None) -> Swarm:
    """The whole swarm of the sharded draw, in one process: the spheres :func:`run` simulates,
    for a one-process run of the same spheres (``Simulator(scene, sharded_spawn(...))``)."""
    n, seed, block = check_draw(scene, n, seed, block)
    return shard_swarm(scene, n, seed, 0, n, block, dt)


def may_start_free(scene: Scene) -> bool:
    """Whether a sphere of ``scene``'s emitter can start beyond the box holding every
    obstacle's reject bounds (the emission region grown by the smallest radius reaching past
    it on some axis): the free-flight step of the frame kernel for every part of a sharded run
    and for the one-process run of the same command alike (``Simulator(free_flight=...)``), so
    that they run the same kernel and agree bit for bit whatever spheres each part holds."""
    from ..simulator import reaches_beyond_bounds

    emitter = scene.emitter
    center = np.asarray(emitter.center, float)
    half = np.asarray(emitter.half_extents, float)
    r_min = float(np.min(emitter.radius))
    # the highest lowest point and the lowest highest point a drawn sphere can have
    return reaches_beyond_bounds(scene.boxes, center + half - r_min, center - half + r_min)


def _placed(swarm: Swarm) -> bool:
    """Whether a swarm this module has just drawn with the scene's emitter carries the
    emitter's mark of a placement outside the scene's boxes (an :class:`warpsim.Emitter`
    marks its swarms; another emitter's are checked by the simulator). Nothing can have
    changed it since the draw, so the mark is not hashed again here."""
    return swarm._clear_of is not None


def _with(swarm: Swarm, **changes) -> Swarm:
    """``swarm``, just drawn, with some fields changed; it keeps the mark of its placement
    outside the boxes when neither its positions nor its radii changed (the mark is the digest
    of those and of the boxes, so it is carried over, not computed again)."""
    out = Swarm(**{name: changes.get(name, getattr(swarm, name)) for name in FIELDS})
    if _placed(swarm) and not {"position", "radius"} & changes.keys():
        out._clear_of = swarm._clear_of
    return out


def plan_shards(n: int, shards: int, block: int = DEFAULT_BLOCK) -> list[tuple[int, int]]:
    """``shards`` contiguous sphere ranges ``(start, stop)`` of whole blocks, nearly equal.

    At most one shard per block: asking for more shards than blocks gives one per block.
    """
    n = check.positive_int("n", n)
    block = check.positive_int("block", block)
    shards = check.positive_int("shards", shards)
    blocks = block_count(n, block)
    edges = np.linspace(0, blocks, min(shards, blocks) + 1).round().astype(np.int64)
    return [(int(a) * block, min(int(b) * block, n))
            for a, b in zip(edges[:-1], edges[1:], strict=True) if b > a]
