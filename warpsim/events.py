"""Contact events of a run: one row per contact, as numpy columns; Parquet files for analysis.

Parquet needs pyarrow, the optional ``events`` extra: ``pip install "warpsim[events]"``;
:meth:`ContactEvents.to_pandas` needs pandas.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: Parquet column -> (ContactEvents field, component or None). Vectors are split in x, y, z.
_COLUMNS = {"frame": ("frame", None), "fraction": ("fraction", None),
            "sphere": ("sphere", None), "box": ("box", None),
            "position_x": ("position", 0), "position_y": ("position", 1),
            "position_z": ("position", 2), "normal_x": ("normal", 0), "normal_y": ("normal", 1),
            "normal_z": ("normal", 2), "normal_speed": ("normal_speed", None),
            "resting": ("resting", None)}
_DTYPES = {"frame": np.int64, "fraction": np.float64, "sphere": np.int64, "box": np.int32,
           "position": np.float64, "normal": np.float64, "normal_speed": np.float64,
           "resting": np.bool_}
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
    """Contacts taken during a run, one row per contact, in the order they happened within each
    frame (sphere by sphere, bounce by bounce).

    Attributes:
        frame: the frame in which the contact happened, (E,) int64: a contact in frame ``k``
            happened between the states recorded as frames ``k - 1`` and ``k``.
        fraction: when, as a fraction of that frame's ``dt``, in [0, 1], (E,) float64.
        sphere: index of the sphere in the swarm, (E,) int64.
        box: index of the obstacle in the scene, (E,) int32.
        position: the sphere's centre at contact [m], (E, 3) float64.
        normal: unit outward normal of the obstacle at the contact, (E, 3) float64.
        normal_speed: speed into the surface just before the contact [m/s], ``-v . n >= 0``,
            (E,) float64.
        resting: True for a resting contact (a supported sphere, not a bounce), (E,) bool.
        dropped: contacts that happened but were not recorded because the event buffer was
            full (its capacity is an option of the run); 0 means the table is complete.

    Raises:
        ValueError: columns of different lengths or wrong shapes, naming the field.
    """

    frame: np.ndarray
    fraction: np.ndarray
    sphere: np.ndarray
    box: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    normal_speed: np.ndarray
    resting: np.ndarray
    dropped: int = field(default=0)

    def __post_init__(self):
        n = None
        for name, dtype in _DTYPES.items():
            values = np.asarray(getattr(self, name))
            width = 3 if name in ("position", "normal") else None
            expected = (values.shape[0],) if width is None else (values.shape[0], width)
            if values.ndim == 0 or values.shape != expected:
                raise ValueError(f"{name} must have shape (E,){'' if width is None else ' x 3'}, "
                                 f"got {values.shape}")
            n = values.shape[0] if n is None else n
            if values.shape[0] != n:
                raise ValueError(f"{name} has {values.shape[0]} rows, frame has {n}")
            setattr(self, name, np.array(values, dtype=dtype, copy=True))
        for name, bad, what in (
                ("fraction", ~((self.fraction >= 0.0) & (self.fraction <= 1.0)), "in [0, 1]"),
                ("normal_speed", ~(self.normal_speed >= 0.0), ">= 0")):
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise ValueError(f"{name}[{i}] must be {what}, got {getattr(self, name)[i]!r}")
        if isinstance(self.dropped, bool) or not isinstance(self.dropped, (int, np.integer)) \
                or self.dropped < 0:
            raise ValueError(f"dropped must be an integer >= 0, got {self.dropped!r}")
        self.dropped = int(self.dropped)

    @classmethod
    def empty(cls, dropped: int = 0) -> ContactEvents:
        """A table without rows."""
        zeros = {name: np.zeros((0, 3) if name in ("position", "normal") else 0, dtype=dtype)
                 for name, dtype in _DTYPES.items()}
        return cls(**zeros, dropped=dropped)

    def __len__(self) -> int:
        return int(self.frame.shape[0])

    def __repr__(self) -> str:
        span = (f", frames {int(self.frame.min())}..{int(self.frame.max())}" if len(self)
                else "")
        return f"ContactEvents({len(self)} contacts{span}, dropped={self.dropped})"

    def columns(self) -> dict[str, np.ndarray]:
        """Flat columns (vectors split into ``_x``, ``_y``, ``_z``), in the Parquet order."""
        out = {}
        for column, (name, component) in _COLUMNS.items():
            values = getattr(self, name)
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

        Columns: ``frame``, ``fraction``, ``sphere``, ``box``, ``position_x/y/z`` [m],
        ``normal_x/y/z``, ``normal_speed`` [m/s], ``resting``; ``dropped`` is stored in the
        file's key-value metadata (``warpsim:dropped``).

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
        from .export.files import atomic_output  # the one atomic-write helper (loads pxr)

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
        missing = [c for c in _COLUMNS if c not in table.column_names]
        if missing:
            raise ValueError(f"{str(path)!r} lacks the columns {missing}: not a warpsim "
                             f"events file")
        cols = {c: table.column(c).to_numpy() for c in _COLUMNS}
        fields = {}
        for name in _DTYPES:
            if name in ("position", "normal"):
                fields[name] = np.stack([cols[f"{name}_{a}"] for a in "xyz"], axis=1) \
                    if len(table) else np.zeros((0, 3))
            else:
                fields[name] = cols[name]
        meta = table.schema.metadata or {}
        return cls(**fields, dropped=int(meta.get(DROPPED_KEY, b"0")))


__all__ = ["ContactEvents", "require_parquet"]
