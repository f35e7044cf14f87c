"""The trade study's plan: its scales, reference settings and knobs, and the rows that
measure them (a knob's value, the run that measures it and its reference run), the
presets' own rows among them (:func:`_preset_rows`).

A run is named by its settings (:func:`run_key`): runs with equal settings run once.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, replace
from typing import Any

from granular_material.procedures.packing import DEFAULT_PRESSURE

__all__ = ["NOISE", "REFERENCE", "SCALES", "SPECIMEN_NEWTON", "Knob", "PlannedRow",
           "StudyScale", "knobs", "plan_runs", "run_key", "tangent_knob", "tangent_settings"]


@dataclass(frozen=True)
class StudyScale:
    """The sizes of one study (``--scale``).

    Attributes:
        name: smoke, cpu or gpu.
        axial_strain: axial strain every test runs to [-].
        confining: confining pressure p0 [Pa].
        seeds: packings of every pure-DEM run (one RVE each).
        discs: values of the discs-per-RVE knob; the largest is its reference.
        base_discs: discs of the other pure-DEM runs.
        strain_steps, safeties, dampings: values of those pure-DEM knobs [-].
        element_discs: discs of the single element's RVE; element_steps: its load steps.
        rtols, stress_floors (fractions of p0), reuse_tols [-], tangents, accelerations
            ("predictor/relaxation"): values of the element knobs.
        meshes: (nx, ny) of the mesh knob; the finest is its reference.
        mesh_discs, mesh_steps: discs per RVE and load steps of the specimens.
        records: records of each pure-DEM curve.
        mesh_replicate: the specimens' Gauss points share one RVE (smoke: a homogeneous
            specimen that converges in a few iterations) instead of one packing each.
    """

    name: str
    axial_strain: float
    seeds: tuple[int, ...]
    discs: tuple[int, ...]
    base_discs: int
    strain_steps: tuple[float, ...]
    safeties: tuple[float, ...]
    dampings: tuple[float, ...]
    element_discs: int
    element_steps: int
    rtols: tuple[float, ...]
    stress_floors: tuple[float, ...]
    tangents: tuple[str, ...]
    accelerations: tuple[str, ...]
    reuse_tols: tuple[float, ...]
    meshes: tuple[tuple[int, int], ...]
    mesh_discs: int
    mesh_steps: int
    confining: float = DEFAULT_PRESSURE
    records: int = 100
    mesh_replicate: bool = False


#: the reference settings: float64, 10⁻⁶ strain per DEM step (10⁻⁵ at smoke scale), the
#: engine's default time step (0.3 of the critical one) and damping (0.1); Newton to
#: rtol 10⁻³ with a stress floor of 0.001 p0, the objective tangent, extrapolating
#: predictor with Aitken relaxation, every RVE stepped (no reuse)
REFERENCE: dict[str, Any] = {
    "strain_per_step": 1.0e-6, "safety": 0.3, "damping": 0.1, "dtype": "float64",
    "rtol": 1.0e-3, "stress_floor": 0.001, "tangent": "objective",
    "acceleration": "extrapolate/aitken", "reuse_tol": 0.0,
}

SCALES: dict[str, StudyScale] = {
    "smoke": StudyScale(
        name="smoke", axial_strain=0.02, seeds=(1, 2), discs=(16, 36), base_discs=16,
        strain_steps=(1.0e-5, 4.0e-5, 1.0e-4), safeties=(0.3, 0.8), dampings=(0.1, 0.3),
        element_discs=16, element_steps=4, rtols=(1.0e-3, 1.0e-2), stress_floors=(0.001,),
        tangents=("objective", "condensed-hold"), accelerations=("extrapolate/aitken",),
        reuse_tols=(0.0, 1.0e-4), meshes=((1, 1), (1, 2)), mesh_discs=16, mesh_steps=2,
        records=20, mesh_replicate=True,
    ),
    "cpu": StudyScale(
        name="cpu", axial_strain=0.08, seeds=(1, 2, 3), discs=(100, 196, 400, 676, 900),
        base_discs=400, strain_steps=(1.0e-6, 3.0e-6, 1.0e-5, 3.0e-5, 1.0e-4),
        safeties=(0.1, 0.3, 0.6, 0.9), dampings=(0.05, 0.1, 0.2, 0.3), element_discs=100,
        element_steps=40, rtols=(1.0e-3, 5.0e-3, 1.0e-2, 2.0e-2),
        stress_floors=(0.001, 0.005, 0.02),
        tangents=("objective", "kruyt-rothenburg", "perturbation", "secant", "condensed",
                  "condensed-hold"),
        accelerations=("tangent/none", "extrapolate/none", "extrapolate/aitken"),
        reuse_tols=(0.0, 1.0e-6, 1.0e-5, 1.0e-4), meshes=((1, 2), (2, 4)), mesh_discs=64,
        mesh_steps=20,
    ),
}


#: the specimens' Newton tolerances: looser than the reference's (rtol 10⁻³ with a 0.001 p0
#: floor took 60–235 iterations a step past the peak on the 2 × 4 mesh of 64-disc RVEs, 14
#: minutes for 15 of 40 steps here), the force test's defaults before the commands took Guo
#: & Zhao's displacement test; the mesh knob is measured at them
SPECIMEN_NEWTON = {"rtol": 5.0e-3, "stress_floor": 5.0e-3}

#: the ``noise`` knob: disc positions moved by this fraction of their radius (random,
#: seeded), the reference otherwise: how far round-off alone carries a chaotic run
NOISE = 1.0e-9

#: full size for a GPU: five seeds, 400-disc elements in 100 load steps, the meshes up to Wu
#: et al.'s 10 × 15 of 400-disc RVEs, to 10 % axial strain
SCALES["gpu"] = replace(
    SCALES["cpu"], name="gpu", axial_strain=0.1, seeds=(1, 2, 3, 4, 5), element_discs=400,
    element_steps=100, meshes=((2, 4), (5, 10), (10, 15)), mesh_discs=400, mesh_steps=100,
)


@dataclass(frozen=True)
class Knob:
    """One setting varied: its ``name`` (a key of the run settings), the ``test`` that
    carries it, its ``values`` and the value of its reference run."""

    name: str
    test: str
    values: tuple[Any, ...]
    reference: Any


def tangent_settings(value: str) -> dict[str, str]:
    """The material tangent and Newton's tangent update that a value of the tangent knob
    names: "secant" is the objective tangent with Broyden updates, "<tangent>-hold" that
    tangent held over each increment, any other the material tangent of every iterate."""
    if value == "secant":
        return {"tangent": "objective", "tangent_update": "secant"}
    if value.endswith("-hold"):
        return {"tangent": value.removesuffix("-hold"), "tangent_update": "hold"}
    return {"tangent": value, "tangent_update": "none"}


def tangent_knob(tangent: str, update: str) -> str:
    """The tangent knob's value of a material tangent and Newton's update of it (the
    inverse of :func:`tangent_settings`)."""
    if update == "secant":
        return "secant"
    return f"{tangent}-hold" if update == "hold" else tangent


def knobs(scale: StudyScale) -> list[Knob]:
    """The knobs of a study, in the order of the report."""
    ref = _reference(scale)
    return [
        Knob("discs", "dem", scale.discs, max(scale.discs)),
        Knob("strain_per_step", "dem", scale.strain_steps, ref["strain_per_step"]),
        Knob("safety", "dem", scale.safeties, ref["safety"]),
        Knob("damping", "dem", scale.dampings, ref["damping"]),
        Knob("dtype", "dem", ("float64", "float32"), "float64"),
        Knob("rtol", "element", scale.rtols, ref["rtol"]),
        Knob("stress_floor", "element", scale.stress_floors, ref["stress_floor"]),
        Knob("tangent", "element", scale.tangents, ref["tangent"]),
        Knob("acceleration", "element", scale.accelerations, ref["acceleration"]),
        Knob("reuse_tol", "element", scale.reuse_tols, ref["reuse_tol"]),
        Knob("mesh", "specimen", tuple(f"{nx}x{ny}" for nx, ny in scale.meshes),
             "{}x{}".format(*max(scale.meshes, key=lambda m: m[0] * m[1]))),
        Knob("noise", "dem", (NOISE,), 0.0),
        Knob("noise", "element", (NOISE,), 0.0),
    ]


def _reference(scale: StudyScale) -> dict[str, Any]:
    """The reference settings at this scale (smoke runs 10⁻⁵ strain per DEM step)."""
    ref = dict(REFERENCE)
    ref["strain_per_step"] = min(scale.strain_steps)
    return ref


def _settings(scale: StudyScale, test: str, **change: Any) -> dict[str, Any]:
    """The full settings of one run of ``test``: the reference with ``change``."""
    values = {**_reference(scale), **change}
    noise = {"noise": values["noise"]} if values.get("noise") else {}
    if test == "dem":
        values.setdefault("discs", scale.base_discs)
        return {k: values[k] for k in ("discs", "strain_per_step", "safety", "damping",
                                       "dtype")} | {"test": "dem"} | noise
    common = {k: values[k] for k in ("rtol", "stress_floor", "tangent", "acceleration",
                                     "reuse_tol")}
    # a preset's Newton test and drive where they are not the study's (the force test,
    # every trial from the committed state): absent otherwise, so that the knobs' run keys
    # stay those of earlier studies
    common |= {k: values[k] for k in ("convergence", "drive") if k in values}
    if test == "element":
        return common | {"test": "element",
                         "discs": values.get("discs", scale.element_discs)} | noise
    finest = max(scale.meshes, key=lambda m: m[0] * m[1])
    return common | SPECIMEN_NEWTON | {"test": "specimen", "discs": scale.mesh_discs,
                                       "mesh": values.get("mesh", "{}x{}".format(*finest))}


def run_key(settings: dict[str, Any]) -> str:
    """A short stable name of a run's settings (its curve file and ``trade.csv`` key)."""
    text = json.dumps(settings, sort_keys=True, default=str)
    return f"{settings['test']}-{hashlib.sha1(text.encode()).hexdigest()[:10]}"


@dataclass
class PlannedRow:
    """One row of ``trade.csv``: a knob's value, the run that measures it and its
    reference run."""

    knob: str
    value: Any
    settings: dict[str, Any]
    reference: dict[str, Any]
    per_seed: bool = True  # pure DEM: compare seed by seed (False: with the seeds' mean)


def plan_runs(scale: StudyScale) -> list[PlannedRow]:
    """The rows of the study, knob by knob."""
    rows = []
    for knob in knobs(scale):
        reference = _settings(scale, knob.test, **{knob.name: knob.reference})
        for value in knob.values:
            rows.append(PlannedRow(knob.name, value,
                                   _settings(scale, knob.test, **{knob.name: value}),
                                   reference, per_seed=knob.name != "discs"))
    return rows



def _preset_rows(presets: dict[str, dict[str, Any]], scale: StudyScale) -> list[PlannedRow]:
    """The presets measured: a pure-DEM run and a single-element run of each (its Newton
    test, tangent, relaxation and reuse; the force test's floor where it has one)."""
    rows = []
    for name, values in presets.items():
        dem = {k: values[k] for k in ("discs", "strain_per_step")}
        element = {"rtol": values["rtol"], "tangent": tangent_knob(values["tangent"],
                                                                   values["tangent_update"]),
                   "acceleration": values["acceleration"], "reuse_tol": values["reuse_tol"],
                   "stress_floor": values["stress_floor"]
                   if values.get("stress_floor") is not None else REFERENCE["stress_floor"]}
        if values.get("convergence", "force") != "force":
            element["convergence"] = values["convergence"]
        if values.get("drive", "restart") != "restart":
            element["drive"] = values["drive"]
        rows.append(PlannedRow("preset", name, _settings(scale, "dem", **dem),
                               _settings(scale, "dem", discs=max(scale.discs)),
                               per_seed=False))
        rows.append(PlannedRow("preset", name, _settings(scale, "element", **element),
                               _settings(scale, "element")))
    return rows
