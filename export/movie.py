"""A movie of a warpsim USD file: every k-th recorded frame drawn by the preview renderer, encoded
with imageio (``.mp4`` through its ffmpeg plugin, ``.gif`` through Pillow).

imageio and imageio-ffmpeg are the optional ``movie`` extra: ``pip install "warpsim[movie]"``.
"""

from __future__ import annotations

import importlib
from pathlib import Path

import numpy as np

from .files import atomic_output
from .preview import AZIMUTH_DEG, ELEVATION_DEG, Renderer, _size, _view_angles, scene_bounds
from .usd_read import read_usd, read_usd_boxes

MOVIE_SUFFIXES = (".mp4", ".gif")
GIF_TICK_S = 0.01  # GIF frame durations are whole hundredths of a second
MP4_QUALITY = 8  # imageio-ffmpeg's 0..10 scale: visually clean, a few MB per minute at 960x540


def _require(module: str, extra_hint: str):
    try:
        return importlib.import_module(module)
    except ImportError:
        raise ModuleNotFoundError(f"{extra_hint} is needed for movies: "
                                  f'pip install "warpsim[movie]"') from None


def movie_format(path) -> str:
    """``"mp4"`` or ``"gif"`` from a movie path's extension (any case).

    Raises:
        ValueError: another extension.
    """
    suffix = Path(path).suffix.lower()
    if suffix not in MOVIE_SUFFIXES:
        raise ValueError(f"movie must end in .mp4 or .gif, got {str(path)!r}")
    return suffix[1:]


def check_movie_support(path) -> str:
    """Check, before any drawing, that the movie at ``path`` can be encoded here.

    Returns:
        The format, ``"mp4"`` or ``"gif"``.

    Raises:
        ValueError: a bad extension. ModuleNotFoundError: imageio (or imageio-ffmpeg for mp4)
            is missing; the message names the extra to install.
    """
    fmt = movie_format(path)
    _require("imageio", "imageio")
    if fmt == "mp4":
        _require("imageio_ffmpeg", "imageio-ffmpeg (imageio's ffmpeg plugin)")
    return fmt


def render_movie(usd_path, movie_path, *, every: int = 1, size=(960, 540),
                 azimuth: float = AZIMUTH_DEG, elevation: float = ELEVATION_DEG,
                 progress: bool = False) -> Path:
    """Draw every ``every``-th recorded frame of a warpsim USD file and encode them as a movie.

    The camera is fixed for the whole movie and frames the obstacles and every sphere position
    of the frames drawn (the preview's three-quarter view, or ``azimuth``/``elevation``). The
    movie plays at the simulation's speed: its frame rate is ``1 / (dt * step * every)`` for
    recorded frames ``step`` simulation frames apart (GIF rounds each frame's duration to
    :data:`GIF_TICK_S`). Written atomically: on error nothing is left behind.

    Args:
        usd_path: a file written by :func:`warpsim.export.write_usd`.
        movie_path: ``.mp4`` (H.264, needs an even width and height) or ``.gif``.
        every: draw one recorded frame in ``every`` (the last is always drawn), >= 1.
        size: ``(width, height)`` [px], each >= 8.
        azimuth, elevation: view direction [deg] (see :meth:`Camera.framing`).
        progress: show a tqdm progress bar on standard error.

    Returns:
        ``movie_path`` as a :class:`pathlib.Path`.

    Raises:
        ValueError: bad extension, size, angles or ``every``; a file not written by warpsim.
        ModuleNotFoundError: imageio (or imageio-ffmpeg) missing, naming the extra.
        FileNotFoundError: no file at ``usd_path``, or the movie's folder does not exist.
    """
    movie_path = Path(movie_path)
    fmt = check_movie_support(movie_path)
    width, height = _size(size)
    _view_angles(azimuth, elevation)
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
        raise ValueError(f"every must be an integer >= 1, got {every!r}")
    if fmt == "mp4" and (width % 2 or height % 2):
        raise ValueError(f"mp4 needs an even width and height, got {width}x{height}")
    if not movie_path.parent.is_dir():
        raise FileNotFoundError(f"folder of {str(movie_path)!r} does not exist")

    traj = read_usd(usd_path)
    boxes = read_usd_boxes(usd_path)
    rows = np.unique(np.r_[np.arange(0, len(traj), every), len(traj) - 1])
    lo, hi = scene_bounds(boxes, traj.position[rows], traj.radius)
    renderer = Renderer(boxes, lo, hi, size=(width, height), azimuth=azimuth,
                        elevation=elevation)
    seconds = float(traj.dt) * (float(np.median(np.diff(traj.frame[rows])))
                                if rows.size > 1 else 1.0)

    import imageio.v2 as imageio
    from tqdm import tqdm

    bar = tqdm(total=rows.size, unit="frame", desc=f"movie {movie_path.name}",
               disable=not progress, leave=False)
    with atomic_output(movie_path) as tmp:
        if fmt == "mp4":
            writer = imageio.get_writer(tmp, format="FFMPEG", mode="I", fps=1.0 / seconds,
                                        codec="libx264", quality=MP4_QUALITY,
                                        macro_block_size=1, pixelformat="yuv420p")
        else:
            duration_ms = 1000.0 * max(GIF_TICK_S, round(seconds / GIF_TICK_S) * GIF_TICK_S)
            writer = imageio.get_writer(tmp, format="GIF", mode="I", duration=duration_ms,
                                        loop=0)
        try:
            for row in rows:
                image = renderer.draw(traj.position[row], traj.orientation[row], traj.radius)
                writer.append_data(np.asarray(image))
                bar.update(1)
        finally:
            writer.close()
            bar.close()
    return movie_path
