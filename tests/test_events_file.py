"""Contact events, file side: the table's checks, Parquet round trip (the ``events`` extra),
atomic writes, pandas."""

import sys

import numpy as np
import pytest

from warpsim import ContactEvents, ContactKind


def make_events(n=7, seed=0, dropped=0):
    rng = np.random.default_rng(seed)
    normal = rng.normal(size=(n, 3))
    return ContactEvents.of_frames(
        1 / 60, frame=np.sort(rng.integers(1, 100, n)), fraction=rng.uniform(0, 1, n),
        sphere=rng.integers(0, 1_000_000_000_000, n), box=rng.integers(0, 50, n).astype(np.int32),
        position=rng.normal(size=(n, 3)) * 1e4,
        normal=normal / np.linalg.norm(normal, axis=1, keepdims=True),
        normal_speed=rng.uniform(0, 300, n), kind=rng.random(n) < 0.3, dropped=dropped)


def test_columns_have_their_types_and_inputs_are_copied():
    frame = np.array([3, 4])
    events = ContactEvents.of_frames(0.5, frame=frame, fraction=[0.0, 1.0], sphere=[1, 2],
                                     box=[0, 5], position=[[0, 0, 0], [1, 2, 3]],
                                     normal=[[0, 1, 0], [1, 0, 0]], normal_speed=[0.0, 2.5],
                                     kind=[ContactKind.SUPPORT, ContactKind.BOUNCE])
    frame[0] = 99
    assert events.frame.tolist() == [3, 4]  # a copy, not a view of the caller's array
    assert events.time.tolist() == [1.0, 2.0]  # (frame - 1 + fraction) dt
    assert (events.frame.dtype, events.fraction.dtype, events.sphere.dtype, events.box.dtype,
            events.kind.dtype) == (np.int64, np.float64, np.int64, np.int32, np.int8)
    assert len(events) == 2 and events.dropped == 0
    assert repr(events) == "ContactEvents(2 contacts, frames 3..4, dropped=0)"
    assert len(ContactEvents.empty(dropped=4)) == 0
    assert events.bounces().sphere.tolist() == [2] and events.of_sphere(1).box.tolist() == [0]


def test_a_table_without_frames_is_continuous_time():
    """The exact reference's contacts have no frame: time alone, the same columns else."""
    events = ContactEvents(time=[0.25, 0.5], sphere=[0, 0], box=[3, -1],
                           position=[[0, 1, 0]] * 2, normal=[[0, 1, 0]] * 2,
                           normal_speed=[2.0, -0.5], kind=[0, 1])
    assert events.frame is None and events.fraction is None
    assert repr(events) == "ContactEvents(2 contacts, 0.25..0.5 s, dropped=0)"
    both = ContactEvents.concatenate([events, events.select([1])])
    assert both.time.tolist() == [0.25, 0.5, 0.5] and both.kind.tolist() == [0, 1, 1]
    with pytest.raises(ValueError, match="frame and fraction go together"):
        ContactEvents(time=[0.0], sphere=[0], box=[0], position=[[0, 0, 0]],
                      normal=[[0, 1, 0]], normal_speed=[1.0], kind=[0], frame=[1])


@pytest.mark.parametrize("field, value, match", [
    ("fraction", [0.5, 1.5], r"fraction\[1\]"), ("fraction", [np.nan, 0.5], r"fraction\[0\]"),
    ("normal_speed", [1.0, -0.1], r"normal_speed\[1\] must be >= 0 for a bounce"),
    ("kind", [0, 2], r"kind\[1\] must be one of \[0, 1\]"), ("box", [0, -2], r"box\[1\]"),
    ("position", [[0, 0, 0]], "position has 1 rows"), ("normal", [0, 1, 0], "normal must"),
    ("dropped", -1, "dropped"), ("dropped", True, "dropped")])
def test_bad_tables_are_refused_naming_the_field(field, value, match):
    good = dict(time=[0.5, 1.5], frame=[1, 2], fraction=[0.5, 0.5], sphere=[0, 1], box=[0, 0],
                position=[[0, 0, 0]] * 2, normal=[[0, 1, 0]] * 2, normal_speed=[1.0, 1.0],
                kind=[0, 0])
    good[field] = value
    with pytest.raises(ValueError, match=match):
        ContactEvents(**good)


def test_parquet_round_trip_is_exact(tmp_path):
    pytest.importorskip("pyarrow")
    events = make_events(dropped=12)
    out = events.write_parquet(tmp_path / "hits.parquet")
    back = ContactEvents.read_parquet(out)
    for name in ("frame", "fraction", "time", "sphere", "box", "position", "normal",
                 "normal_speed", "kind"):
        np.testing.assert_array_equal(getattr(back, name), getattr(events, name))
        assert getattr(back, name).dtype == getattr(events, name).dtype
    assert back.dropped == 12
    empty = ContactEvents.empty().write_parquet(tmp_path / "none.parquet")
    assert len(ContactEvents.read_parquet(empty)) == 0


def test_parquet_columns_for_other_tools(tmp_path):
    pq = pytest.importorskip("pyarrow.parquet")
    events = make_events()
    table = pq.read_table(events.write_parquet(tmp_path / "hits.parquet"))
    assert table.column_names == ["frame", "fraction", "time", "sphere", "box", "position_x",
                                  "position_y", "position_z", "normal_x", "normal_y",
                                  "normal_z", "normal_speed", "kind"]
    np.testing.assert_array_equal(table.column("position_y").to_numpy(), events.position[:, 1])


def test_failed_write_keeps_the_existing_file(tmp_path, monkeypatch):
    pq = pytest.importorskip("pyarrow.parquet")
    path = tmp_path / "hits.parquet"
    path.write_bytes(b"previous")

    def partial(table, where, **kwargs):
        with open(where, "wb") as f:
            f.write(b"PAR1 half")
        raise OSError("disk full")

    monkeypatch.setattr(pq, "write_table", partial)
    with pytest.raises(OSError, match="disk full"):
        make_events().write_parquet(path)
    assert path.read_bytes() == b"previous"
    assert [p.name for p in tmp_path.iterdir()] == ["hits.parquet"]


def test_bad_paths_and_missing_extra(tmp_path, monkeypatch):
    with pytest.raises(ValueError, match=r"\.parquet"):
        make_events().write_parquet(tmp_path / "hits.csv")
    with pytest.raises(FileNotFoundError):
        make_events().write_parquet(tmp_path / "missing" / "hits.parquet")
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # as if the extra were not installed
    with pytest.raises(ModuleNotFoundError, match=r"warpsim\[events\]"):
        make_events().write_parquet(tmp_path / "hits.parquet")
    assert list(tmp_path.iterdir()) == []


def test_hits_per_box_with_pandas():
    pytest.importorskip("pandas")
    events = make_events(n=200, seed=3)
    df = events.to_pandas()
    hits = df[df.kind == ContactKind.BOUNCE].groupby("box").size()
    bounce = events.kind == ContactKind.BOUNCE
    expected = np.bincount(events.box[bounce], minlength=50)
    for box, count in hits.items():
        assert count == expected[box]
    assert hits.sum() == np.count_nonzero(bounce)
    assert df.attrs["dropped"] == 0


def test_readme_hits_per_box_example_runs(tmp_path, monkeypatch, capsys):
    """The README's pandas example (hits per box) runs on a file written by write_parquet."""
    import re
    from pathlib import Path

    pytest.importorskip("pandas")
    pytest.importorskip("pyarrow")
    readme = Path(__file__).resolve().parents[1] / "README.md"
    if not readme.is_file():
        pytest.skip("README.md not present (installed package)")
    blocks = re.findall(r"```python\n(.*?)```", readme.read_text(encoding="utf-8"), flags=re.S)
    code = next(b for b in blocks if "hits.parquet" in b)
    events = make_events(n=50, seed=8)
    events.write_parquet(tmp_path / "hits.parquet")
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "README.md", "exec"), {})  # noqa: S102
    printed = capsys.readouterr().out
    assert "mean_speed" in printed and "hits" in printed
    boxes_hit = np.unique(events.bounces().box)
    lines = [line.split()[0] for line in printed.strip().splitlines()[2:]]  # rows after header
    assert lines == [str(b) for b in boxes_hit]  # one row per box hit, in box order
