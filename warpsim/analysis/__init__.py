"""How far from the true motion a run is: the exact float64 reference (:mod:`.reference`), the
error report comparing a run with it (:mod:`.error_report`), and the accuracy study of error
against cost (:mod:`.accuracy`, whose plots need the ``plots`` extra, imported only then).

``compare(sim_or_trajectory, scene, swarm, sample=32)`` is the error report of a run;
``simulate(scene, swarm, t_end, times)`` the reference's own motion.
"""

from . import error_report, reference
from .error_report import ErrorReport, compare
from .reference import ReferenceRun, simulate

__all__ = ["ErrorReport", "ReferenceRun", "accuracy", "compare", "error_report", "reference",
           "simulate"]


def __getattr__(name):
    if name == "accuracy":  # on first use: ``python -m warpsim.analysis.accuracy`` runs it
        import importlib

        return importlib.import_module(".accuracy", __name__)
    raise AttributeError(f"module 'warpsim.analysis' has no attribute {name!r}")
