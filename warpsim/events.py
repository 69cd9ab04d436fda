"""The contact table: one row per contact, as numpy columns; Parquet files for analysis.

Parquet needs pyarrow, the optional ``events`` extra: ``pip install "warpsim[events]"``;
:meth:`ContactEvents.to_pandas` needs pandas.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .vocabulary import ContactKind

#: Parquet column -> (ContactEvents field, component or None). Vectors are split in x, y, z.
_COLUMNS = {"frame": ("frame", None), "fraction": ("fraction", None), "time": ("time", None),
            "sphere": ("sphere", None), "box": ("box", None),
            "position_x": ("position", 0), "position_y": ("position", 1),
            "position_z": ("position", 2), "normal_x": ("normal", 0), "normal_y": ("normal", 1),
            "normal_z": ("normal", 2), "normal_speed": ("normal_speed", None),
            "kind": ("kind", None)}
_DTYPES = {"time": np.float64, "sphere": np.int64, "box": np.int32, "position": np.float64,
           "normal": np.float64, "normal_speed": np.float64, "kind": np.int8}
_FRAME_DTYPES = {"frame": np.int64, "fraction": np.float64}  # simulated runs only
_VECTORS = ("position", "normal")
DROPPED_KEY = b"warpsim:dropped"  # Parquet key-value metadata holding ContactEvents.dropped
SUFFIX = ".parquet"


def _pyarrow():
    try:
        pa = importlib.import_module("pyarrow")
        pq = importlib.import_module("pyarrow.parquet")
    except ImportError:
        raise ModuleNotFoundError('pyarrow is needed for events files: '
                                  'pip install "warpsim[events]"') from None
    return pa, pq


def require_parquet() -> None:
    """Check that events files can be written here (before a long run).

    Raises:
        ModuleNotFoundError: pyarrow is missing; the message names the extra.
    """
    _pyarrow()


@dataclass(repr=False)
class ContactEvents:
    """The contact table of warpsim: one row per contact, as numpy columns. A simulated run's
    contacts (:attr:`warpsim.Trajectory.events`), the exact reference's
    (:attr:`warpsim.analysis.ReferenceRun.events`) and those the error report reads from a run's
    frames are all this table.

    Rows are ordered by sphere and time within a frame, by frame first for a simulated run
    (sphere by sphere within a frame, bounce by bounce), by sphere then time for the reference.

    Attributes:
        time: when [s] since the run's start (frame 0), (E,) float64; for a simulated run
            ``(frame - 1 + fraction) * dt``.
        sphere: index of the sphere in the swarm, (E,) int64.
        box: index of the obstacle in the scene, (E,) int32; -1 where unknown (contacts read
            from frames).
        position: the sphere's centre at contact [m], world frame, (E, 3) float64.
        normal: unit outward normal of the obstacle at the contact, world frame, (E, 3) float64.
        normal_speed: speed into the surface just before the contact [m/s], ``-v . n``, (E,)
            float64: >= 0 for a bounce, any sign for a support a sphere slides onto, NaN where
            unknown.
        kind: :class:`warpsim.ContactKind` of each row, (E,) int8.
        frame: simulated runs: the frame in which the contact happened, (E,) int64 (between
            the states recorded as frames ``frame - 1`` and ``frame``); None for continuous time.
        fraction: simulated runs: when, as a fraction of that frame's ``dt``, in [0, 1], (E,)
            float64; None with ``frame``.
        dropped: contacts that happened but were not recorded because the event buffer was
            full (its capacity is an option of the run); 0 means the table is complete.

    Raises:
        ValueError: columns of different lengths or wrong shapes, or a bad value, naming the
            field and the row.
    """

    time: np.ndarray
    sphere: np.ndarray
    box: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    normal_speed: np.ndarray
    kind: np.ndarray
    frame: np.ndarray | None = None
    fraction: np.ndarray | None = None
    dropped: int = field(default=0)

    def __post_init__(self):
        if (self.frame is None) != (self.fraction is None):
            raise ValueError("frame and fraction go together: give both or neither")
        dtypes = dict(_DTYPES, **(_FRAME_DTYPES if self.frame is not None else {}))
        n = None
        for name, dtype in dtypes.items():
            values = np.asarray(getattr(self, name))
            width = 3 if name in _VECTORS else None
            expected = (values.shape[0],) if width is None else (values.shape[0], width)
            if values.ndim == 0 or values.shape != expected:
                raise ValueError(f"{name} must have shape (E,){'' if width is None else ' x 3'}, "
                                 f"got {values.shape}")
            n = values.shape[0] if n is None else n
            if values.shape[0] != n:
                raise ValueError(f"{name} has {values.shape[0]} rows, time has {n}")
            setattr(self, name, np.array(values, dtype=dtype, copy=True))
        bounce = self.kind == ContactKind.BOUNCE
        checks = [("time", ~(self.time >= 0.0), ">= 0"), ("box", self.box < -1, ">= -1"),
                  ("kind", ~np.isin(self.kind, list(ContactKind)),
                   f"one of {[int(k) for k in ContactKind]}"),
                  ("normal_speed", bounce & (self.normal_speed < 0.0), ">= 0 for a bounce")]
        if self.fraction is not None:
            checks.append(("fraction", ~((self.fraction >= 0.0) & (self.fraction <= 1.0)),
                           "in [0, 1]"))
        for name, bad, what in checks:
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise ValueError(f"{name}[{i}] must be {what}, got {getattr(self, name)[i]!r}")
        if isinstance(self.dropped, bool) or not isinstance(self.dropped, (int, np.integer)) \
                or self.dropped < 0:
            raise ValueError(f"dropped must be an integer >= 0, got {self.dropped!r}")
        self.dropped = int(self.dropped)

    @classmethod
    def of_frames(cls, dt: float, frame, fraction, **columns) -> ContactEvents:
        """A simulated run's table: ``time`` from ``frame``, ``fraction`` and the step ``dt``
        [s] (float64); the other columns as the class takes them."""
        frame = np.asarray(frame, dtype=np.int64)
        fraction = np.asarray(fraction, dtype=np.float64)
        return cls(time=(frame - 1 + fraction) * float(dt), frame=frame, fraction=fraction,
                   **columns)

    @classmethod
    def empty(cls, dropped: int = 0, frames: bool = True) -> ContactEvents:
        """A table without rows (``frames``: with the frame and fraction columns)."""
        dtypes = dict(_DTYPES, **(_FRAME_DTYPES if frames else {}))
        zeros = {name: np.zeros((0, 3) if name in _VECTORS else 0, dtype=dtype)
                 for name, dtype in dtypes.items()}
        return cls(**zeros, dropped=dropped)

    @classmethod
    def concatenate(cls, tables: list[ContactEvents]) -> ContactEvents:
        """The rows of ``tables`` one after the other (all with frames or all without; none:
        an empty table without frames); ``dropped`` adds up."""
        if not tables:
            return cls.empty(frames=False)
        names = [n for n in (*_DTYPES, *_FRAME_DTYPES) if getattr(tables[0], n) is not None]
        return cls(**{n: np.concatenate([getattr(t, n) for t in tables]) for n in names},
                   dropped=sum(t.dropped for t in tables))

    def select(self, rows) -> ContactEvents:
        """The rows picked by a boolean mask or an index array (``dropped`` kept)."""
        names = [n for n in (*_DTYPES, *_FRAME_DTYPES) if getattr(self, n) is not None]
        return type(self)(**{n: getattr(self, n)[rows] for n in names}, dropped=self.dropped)

    def of_sphere(self, sphere: int) -> ContactEvents:
        """The contacts of one sphere, in their order."""
        return self.select(self.sphere == sphere)

    def bounces(self) -> ContactEvents:
        """Only the reflections (no supports)."""
        return self.select(self.kind == ContactKind.BOUNCE)

    def __len__(self) -> int:
        return int(self.time.shape[0])

    def __repr__(self) -> str:
        if not len(self):
            span = ""
        elif self.frame is not None:
            span = f", frames {int(self.frame.min())}..{int(self.frame.max())}"
        else:
            span = f", {self.time.min():.6g}..{self.time.max():.6g} s"
        return f"ContactEvents({len(self)} contacts{span}, dropped={self.dropped})"

    def columns(self) -> dict[str, np.ndarray]:
        """Flat columns (vectors split into ``_x``, ``_y``, ``_z``), in the Parquet order."""
        out = {}
        for column, (name, component) in _COLUMNS.items():
            values = getattr(self, name)
            if values is not None:
                out[column] = values if component is None else values[:, component]
        return out

    def to_pandas(self):
        """A :class:`pandas.DataFrame` of :meth:`columns`; ``dropped`` is in ``df.attrs``.

        Raises:
            ModuleNotFoundError: pandas is missing.
        """
        try:
            import pandas as pd
        except ImportError:
            raise ModuleNotFoundError("pandas is needed for to_pandas(): pip install pandas"
                                      ) from None
        df = pd.DataFrame(self.columns())
        df.attrs["dropped"] = self.dropped
        return df

    def write_parquet(self, path) -> Path:
        """Write the table to a Parquet file, atomically (a temporary name, then a rename).

        Columns: ``frame``, ``fraction`` (simulated runs), ``time`` [s], ``sphere``, ``box``,
        ``position_x/y/z`` [m], ``normal_x/y/z``, ``normal_speed`` [m/s], ``kind`` (0 bounce,
        1 support: :class:`warpsim.ContactKind`); ``dropped`` is stored in the file's key-value
        metadata (``warpsim:dropped``).

        Args:
            path: output file ending in ``.parquet``; its folder must exist.

        Returns:
            ``path`` as a :class:`pathlib.Path`.

        Raises:
            ValueError: another extension. FileNotFoundError: the folder does not exist.
            ModuleNotFoundError: pyarrow is missing (the ``events`` extra).
            OSError: the file cannot be written.
        """
        path = Path(path)
        if path.suffix.lower() != SUFFIX:
            raise ValueError(f"events file must end in {SUFFIX}, got {str(path)!r}")
        if not path.parent.is_dir():
            raise FileNotFoundError(f"folder of {str(path)!r} does not exist")
        pa, pq = _pyarrow()
        table = pa.table(self.columns())
        table = table.replace_schema_metadata({DROPPED_KEY: str(self.dropped).encode()})
        from .export.files import atomic_output  # the one atomic writer (standard library)

        with atomic_output(path) as tmp:
            pq.write_table(table, tmp)
        return path

    @classmethod
    def read_parquet(cls, path) -> ContactEvents:
        """Read a file written by :meth:`write_parquet`.

        Raises:
            FileNotFoundError: no file. ValueError: a column is missing.
            ModuleNotFoundError: pyarrow is missing.
        """
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"no events file at {str(path)!r}")
        _, pq = _pyarrow()
        table = pq.read_table(path)
        optional = set(_FRAME_DTYPES)
        missing = [c for c in _COLUMNS if c not in table.column_names and c not in optional]
        if missing:
            raise ValueError(f"{str(path)!r} lacks the columns {missing}: not a warpsim "
                             f"events file")
        cols = {c: table.column(c).to_numpy() for c in _COLUMNS if c in table.column_names}
        fields = {}
        for name in (*_DTYPES, *_FRAME_DTYPES):
            if name in _VECTORS:
                fields[name] = np.stack([cols[f"{name}_{a}"] for a in "xyz"], axis=1) \
                    if len(table) else np.zeros((0, 3))
            else:
                fields[name] = cols.get(name)
        meta = table.schema.metadata or {}
        return cls(**fields, dropped=int(meta.get(DROPPED_KEY, b"0")))


__all__ = ["ContactEvents", "require_parquet"]
