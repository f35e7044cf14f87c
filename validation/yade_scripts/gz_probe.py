"""Instrumentation of Guo & Zhao's ``MultiScale`` for the gz-femxdem case (inside yade).

Imported by their example in place of ``msFEM2D.MultiScale``; their numerics are untouched:
the subclass only counts, before calling their method, the DEM evaluations of every load step
and the DEM steps they run (their ``shear2D`` runs n = max(1e5·max|∇u|, 2) steps per Gauss
point). ``start`` and ``record`` append one JSON line per load step (step 0 included) to
``gz_probe.jsonl`` in the working folder: wall time since ``start`` [s], evaluations and DEM
steps so far, the mesh area [m²] (updated Lagrangian), the volume-average stress [Pa,
tension positive], their platen force and width, and per Gauss point the stress, the
accumulated ∇u and the void ratio.
"""

import json
import time

import esys.escript as escript
import numpy
from msFEM2D import MultiScale as _GuoZhaoMultiScale

OUT = "gz_probe.jsonl"
_state = {"evaluations": 0, "dem_steps": 0, "clock": 0.0}


class MultiScale(_GuoZhaoMultiScale):
    """Guo & Zhao's MultiScale, counting DEM evaluations and DEM steps."""

    def applyStrain_getStressTangentDEM(self, st=None):
        grads = numpy.array(st.toListOfTuples()).reshape(-1, 4)
        _state["evaluations"] += 1
        _state["dem_steps"] += sum(int(max(1e5 * numpy.max(numpy.abs(g)), 2)) for g in grads)
        return super().applyStrain_getStressTangentDEM(st=st)


def _tuples(data):
    return numpy.array(data.toListOfTuples(), dtype=float).tolist()


def _write(row):
    with open(OUT, "a") as fh:
        fh.write(json.dumps(row) + "\n")


def _row(step, prob, void):
    dom = prob.getDomain()
    area = float(escript.integrate(escript.Scalar(1.0, escript.Function(dom))))
    stress = prob.getCurrentStress()
    mean = numpy.array(escript.integrate(stress), dtype=float) / area
    return {"step": step, "wall_s": time.perf_counter() - _state["clock"],
            "evaluations": _state["evaluations"], "dem_steps": _state["dem_steps"],
            "area": area, "mean_stress": mean.tolist(), "stress": _tuples(stress),
            "grad_u": _tuples(prob.getCurrentStrain()), "void_ratio": _tuples(void)}


def start(prob, domain):
    """Write the Gauss points' reference coordinates and the initial state; start the clock."""
    _state["clock"] = time.perf_counter()
    row = _row(0, prob, prob.getLocalVoidRatio())
    row["points"] = _tuples(escript.Function(domain).getX())
    _write(row)


def record(step, prob, void, force_top=None, length_top=None):
    """Append the state after load step ``step`` (``void``: their local void ratios;
    ``force_top`` [N/m], ``length_top`` [m]: their resultant platen force and width)."""
    row = _row(step, prob, void)
    if force_top is not None:
        row["force_top"] = float(force_top)
        row["length_top"] = float(length_top)
    _write(row)
