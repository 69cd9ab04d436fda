"""Without rerun-sdk (the ``viewer`` extra), recordings and the viewer fail with one line naming
the extra, before any simulation; runs whether or not the extra is installed."""

import importlib
import sys

import numpy as np
import pytest

import warpsim as ws
from warpsim.apps import cli


def test_missing_extra_names_it(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "rerun", None)  # import rerun now fails
    traj = ws.Trajectory(frame=np.array([0, 1]), dt=0.1, position=np.zeros((2, 1, 3)),
                         orientation=np.tile([0.0, 0.0, 0.0, 1.0], (2, 1, 1)),
                         radius=np.array([0.5]))
    with pytest.raises(ModuleNotFoundError, match=r"warpsim\[viewer\]"):
        ws.export.write_rerun(tmp_path / "x.rrd", None, traj)
    code = cli.main(["run", "room", "-n", "5", "--frames", "2", "--rerun",
                     str(tmp_path / "x.rrd"), "-o", str(tmp_path / "x.usdc")])
    err = capsys.readouterr().err.strip()
    assert code == cli.EXIT_ERROR and "warpsim[viewer]" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "x.usdc").exists()  # refused before the run
    (tmp_path / "x.rrd").write_bytes(b"")
    assert cli.main(["view", str(tmp_path / "x.rrd")]) == cli.EXIT_ERROR
    assert "warpsim[viewer]" in capsys.readouterr().err
    viewer = importlib.import_module("warpsim.export.rerun_viewer")
    monkeypatch.setattr(viewer.importlib.util, "find_spec", lambda name: None)
    monkeypatch.setattr(viewer.shutil, "which", lambda name: None)
    with pytest.raises(ModuleNotFoundError, match=r"warpsim\[viewer\]"):
        viewer.rerun_executable()
