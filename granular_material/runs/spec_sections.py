"""The sections of a run specification (:mod:`granular_material.runs.spec` says what one is):
the problem (:class:`ProblemSpec`), the Newton solver (:class:`NewtonSpec`), the material
(:class:`MaterialSpec`), the outputs (:class:`OutputSpec`), the regularisation
(:class:`RegularisationSpec`) and adaptivity (:class:`AdaptivitySpec`, which a boundary-value
scene's ``[adaptivity]`` table and the specimen's run share), each field with its default and
its check, once."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, is_dataclass
from pathlib import Path
from typing import Any

from granular_material.errors import ParameterError
from granular_material.fem.boundary_value.biaxial import BiaxialSetup
from granular_material.fem.regularisation import Regularisation, check_element_name
from granular_material.fem.solver.defaults import COMMAND_DEFAULTS
from granular_material.fem.solver.newton import NewtonSettings
from granular_material.procedures.element_tests import DEFAULT_AXIAL_STRAIN
from granular_material.procedures.packing import DEFAULT_DISCS, DEFAULT_PRESSURE
from granular_material.reference_values import TWIN_ELASTIC_WINDOW
from granular_material.runs.spec_checks import (
    SpecError,
    check_map_strains,
    check_newton_bounds,
    check_postprocess,
    check_track,
    conform_fields,
    conform_mapping,
)
from granular_material.vocabulary import renamed

__all__ = ["BACKENDS", "DEFAULT_MOBILISED_FRACTION", "FULL_SCALE", "REDUCED_SCALE", "SCALES",
           "SWITCHES", "TESTS", "AdaptivitySpec", "MaterialSpec", "NewtonSpec", "OutputSpec",
           "ProblemSpec", "RegularisationSpec"]

#: the tests a run specification describes: one element, or the biaxial specimen
TESTS = ("single-element", "biaxial")
#: the reduced CPU scale of the biaxial specimen: elements (nx, ny) and discs per RVE; 5 × 10
#: is the coarsest mesh on which a band showed
REDUCED_SCALE = ((5, 10), 64)
#: the full scale (Wu et al. 2025): 10 × 15 Q4 elements, 600 Gauss points, 400-disc RVEs
FULL_SCALE = ((10, 15), DEFAULT_DISCS)
#: the scales of a biaxial specimen
SCALES = ("full", "reduced")
#: where a material's points live: this process, or shards on the ranks of an MPI job
BACKENDS = ("inprocess", "mpi")
#: width and height [m] of each test's specimen when the spec names none
_SIZES = {"single-element": (1.0, 1.0), "biaxial": (0.05, 0.10)}
#: BiaxialSetup's field names that the spec calls otherwise
_SETUP_NAMES = {"nx": "elements", "ny": "elements", "gauss": "quadrature"}


def _typed(obj: Any) -> None:
    """Every field of the section ``obj`` of its annotated type (SpecError naming it)."""
    conform_fields(obj, error=SpecError)


def _at_least(name: str, value: Any, lowest: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int):
        raise SpecError(name, f"must be an integer >= {lowest}, got {value!r}")
    if value < lowest:
        raise SpecError(name, f"must be >= {lowest}, got {value!r}")


def _one_of(name: str, value: Any, choices: tuple[Any, ...]) -> None:
    if value not in choices:
        raise SpecError(name, f"must be one of {', '.join(map(str, choices))}, got {value!r}")


@dataclass(frozen=True, kw_only=True)
class ProblemSpec:
    """The boundary-value problem: a drained biaxial test, of one element or a specimen.

    Attributes:
        test: "single-element" (one element, 1 m × 1 m) or "biaxial" (the specimen).
        axial_strain: final axial strain of the top platen, compression positive [-].
        confining: lateral confining pressure [Pa], compression positive; also the
            consolidation pressure of RVEs a run prepares.
        steps: load steps to ``axial_strain``.
        element: "quad4", "quad8", "quad9", "tri3" or "tri6".
        quadrature: Gauss points per direction (per triangle: the rule's points); None: the
            element's default.
        width, height: specimen size [m]; None: 1 × 1 (single-element), 0.05 × 0.10
            (biaxial).
        elements: (nx, ny) elements of a biaxial specimen; None: those of ``scale``.
        scale: "full" (Wu et al.'s 10 × 15 elements of 400-disc RVEs) or "reduced" (5 × 10 of
            64 discs) for a biaxial specimen; None: full on CUDA, reduced on a CPU.
        platens: "smooth" (platen nodes slide, one bottom node pinned) or "rough".
    """

    test: str
    axial_strain: float = DEFAULT_AXIAL_STRAIN
    confining: float = DEFAULT_PRESSURE
    steps: int = 100
    element: str = "quad4"
    quadrature: int | None = None
    width: float | None = None
    height: float | None = None
    elements: tuple[int, int] | None = None
    scale: str | None = None
    platens: str = "smooth"

    def __post_init__(self) -> None:
        _typed(self)
        _one_of("test", self.test, TESTS)
        if not (math.isfinite(self.confining) and self.confining > 0):
            raise SpecError("confining", "must be a positive number of Pa (σxx is held at "
                                         "−confining, σ1/σ3 divides by it), got "
                                         f"{self.confining:g}")
        _at_least("steps", self.steps, 1)
        for name in ("width", "height"):
            value = getattr(self, name)
            if value is not None and not value > 0:
                raise SpecError(name, f"must be a length > 0 m, got {value!r}")
        width, height = _SIZES[self.test]
        object.__setattr__(self, "width", width if self.width is None else self.width)
        object.__setattr__(self, "height", height if self.height is None else self.height)
        if self.test == "single-element":
            for name in ("elements", "scale"):
                if getattr(self, name) is not None:
                    raise SpecError(name, "is a biaxial specimen's; a single element has one")
        if self.scale is not None:
            _one_of("scale", self.scale, SCALES)
        if self.elements is not None:
            object.__setattr__(self, "elements", tuple(self.elements))
            if len(self.elements) != 2:
                raise SpecError("elements", f"must be two counts (nx, ny), got {self.elements}")
        self.setup(self.elements or (1, 1))  # the setup's own checks, named as fields here

    def setup(self, elements: tuple[int, int]) -> BiaxialSetup:
        """The FEM problem's setup on a mesh of ``elements`` (nx, ny); a value it refuses is
        a SpecError naming the field of this spec."""
        nx, ny = elements
        try:
            return BiaxialSetup(width=self.width, height=self.height, nx=nx, ny=ny,
                                confining=self.confining, axial_strain=self.axial_strain,
                                platens=self.platens, element=self.element,
                                gauss=self.quadrature)
        except ParameterError as exc:
            raise SpecError(_SETUP_NAMES.get(exc.field, exc.field), exc.message) from None

    def resolved_scale(self, device: str) -> str:
        """The biaxial scale that runs on ``device``: the given one, else full on CUDA."""
        return self.scale or ("full" if device.startswith("cuda") else "reduced")

    def mesh(self, device: str) -> tuple[tuple[int, int], int | None]:
        """(nx, ny) of the mesh on ``device`` and the discs per RVE of its scale (None for a
        single element, whose discs are the material's)."""
        if self.test == "single-element":
            return (1, 1), None
        (nx, ny), discs = FULL_SCALE if self.resolved_scale(device) == "full" else REDUCED_SCALE
        return (self.elements or (nx, ny)), discs


def _newton_default(name: str) -> Any:
    """The commands' default of a NewtonSettings field (COMMAND_DEFAULTS, else the class's)."""
    return COMMAND_DEFAULTS.get(name, getattr(NewtonSettings, name))


@dataclass(frozen=True, kw_only=True)
class NewtonSpec:
    """The Newton solver of the run (:class:`~granular_material.fem.NewtonSettings`, with the
    commands' defaults: :data:`~granular_material.fem.solver.defaults.COMMAND_DEFAULTS`).

    Attributes:
        rtol: relative tolerance of the convergence test [-]; None: 1e-2 for a noisy
            material, 1e-4 otherwise.
        stress_tol: absolute tolerance as a stress error [Pa]; None: 0.005 × confining for
            a noisy (DEM) material, else 0.
        stall_rtol: accept a stalled residual below this [-]; None: 2 × rtol for a noisy
            material, else 0 (off).
        accept_correction: accept a stalled increment once ‖δu‖/‖Δu‖ is at most this [-];
            None: 1e-2 for a noisy material, else 0 (off).
        relaxation: "none" or "aitken"; None: aitken for a noisy material (none with
            secant updates), else none.
        tangent_update: "none", "secant" or "hold"; None: hold for a noisy material, else
            none.
        convergence: "force", "displacement" or "residual-displacement"; None:
            residual-displacement for a noisy material, force otherwise
            (:func:`~granular_material.fem.solver.defaults.default_settings`).
        stall_window, max_iterations, max_cutbacks, predictor, formulation,
        secant_min_change, continuation, arc_length_steps: as
            :class:`~granular_material.fem.NewtonSettings` (``continuation = "arc-length"``
            follows the path past limit points; see
            :mod:`granular_material.fem.solver.continuation`).
    """

    rtol: float | None = None
    stress_tol: float | None = None
    stall_rtol: float | None = None
    accept_correction: float | None = None
    stall_window: int = _newton_default("stall_window")
    max_iterations: int = _newton_default("max_iterations")
    max_cutbacks: int = _newton_default("max_cutbacks")
    convergence: str | None = None
    predictor: str = _newton_default("predictor")
    formulation: str = _newton_default("formulation")
    relaxation: str | None = None
    tangent_update: str | None = None
    secant_min_change: float = _newton_default("secant_min_change")
    continuation: str = _newton_default("continuation")
    arc_length_steps: float = _newton_default("arc_length_steps")

    def __post_init__(self) -> None:
        _typed(self)
        check_newton_bounds(self.max_cutbacks, self.max_iterations)
        if self.stress_tol is not None and not (math.isfinite(self.stress_tol)
                                                and self.stress_tol >= 0):
            raise SpecError("stress_tol", f"must be a stress >= 0 Pa, got {self.stress_tol:g}")
        self.settings(noisy=False)

    def settings(self, noisy: bool) -> NewtonSettings:
        """The solver's settings for a material whose stress is ``noisy`` (DEM RVEs); a value
        NewtonSettings refuses is a SpecError naming its field."""
        from granular_material.fem.solver.defaults import default_settings

        values = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "stress_tol"}
        try:
            return default_settings(noisy, **values)
        except ParameterError as exc:
            if exc.field in values:
                raise SpecError(exc.field, exc.message) from None
            raise

    def convergence_test(self, noisy: bool) -> str:
        """The convergence test of the run for a material whose stress is ``noisy``."""
        return self.settings(noisy).convergence

    def stress_tolerance(self, noisy: bool, confining: float) -> float:
        """The absolute tolerance [Pa] of the run."""
        from granular_material.fem.solver.defaults import default_stress_tol

        return default_stress_tol(noisy, confining) if self.stress_tol is None else self.stress_tol


@dataclass(frozen=True, kw_only=True)
class MaterialSpec:
    """The material at the Gauss points: an entry point of ``granular_material.materials``
    and its own parameters (an instance of the material class's ``Parameters``, a frozen
    dataclass, where it has one; else a mapping of keywords for its constructor).

    Attributes:
        name: the entry-point name ("dem", "linear-elastic", or a third party's).
        parameters: the material's parameters; a mapping is turned into ``Parameters``.
    """

    name: str
    parameters: Any = None

    def __post_init__(self) -> None:
        from granular_material.fem.materials.protocol import load_material

        if not isinstance(self.name, str):
            raise SpecError("material", f"must name the material (a string), got "
                                        f"{self.name!r}")
        try:
            cls = load_material(self.name)
        except ValueError:
            from granular_material.fem.materials.protocol import available_materials

            raise SpecError("material", f"{self.name!r} is no installed material (they are "
                                        f"{', '.join(available_materials())})") from None
        kind = getattr(cls, "Parameters", None)
        given = self.parameters
        if kind is None:
            if given is not None and not isinstance(given, Mapping):
                raise SpecError("material", f"parameters of {self.name} must be a mapping of "
                                            f"keywords, got {type(given).__name__}")
            object.__setattr__(self, "parameters", dict(given or {}))
            return
        if isinstance(given, kind):
            return
        if given is not None and not isinstance(given, Mapping):
            raise SpecError("material", f"parameters of {self.name} must be a "
                                        f"{kind.__name__} or a mapping, got {type(given)}")
        known = {f.name for f in fields(kind)}
        given = renamed(dict(given or {}), self.name)  # old names: warned, read as new
        unknown = sorted(set(given) - known)
        if unknown:
            raise SpecError(unknown[0], f"is no parameter of the material {self.name} "
                                        f"(it has {', '.join(sorted(known))})")
        values = conform_mapping(kind, dict(given or {}), error=SpecError)
        try:
            object.__setattr__(self, "parameters", kind(**values))
        except SpecError:
            raise
        except ParameterError as exc:  # the material's own check, named as the spec's field
            raise SpecError(exc.field, exc.message) from None

    @property
    def cls(self) -> type:
        """The material class."""
        from granular_material.fem.materials.protocol import load_material

        return load_material(self.name)

    @property
    def noisy(self) -> bool:
        """Whether the material's stress carries noise (DEM RVEs): it gets the looser
        Newton defaults of :class:`NewtonSpec`."""
        return bool(getattr(self.cls, "noisy", False))

    def values(self) -> dict[str, Any]:
        """The parameters as a plain dict (flat names)."""
        if is_dataclass(self.parameters):
            return {f.name: getattr(self.parameters, f.name) for f in fields(self.parameters)}
        return dict(self.parameters)


@dataclass(frozen=True, kw_only=True)
class RegularisationSpec:
    """The regularisation of the FEM problem (:mod:`granular_material.fem.regularisation`):
    a scene's ``[regularisation]`` table.

    Attributes:
        model: "none" (the classical medium, default) or "second-gradient" (Chambon's
            local second gradient; quad8, quad9 or tri6 elements).
        internal_length: ℓ [m] of the second gradient (its modulus D = G₀ (ℓ/10)²), > 0 with
            "second-gradient", 0 without.
    """

    model: str = "none"
    internal_length: float = 0.0

    def __post_init__(self) -> None:
        _typed(self)
        self.regularisation()

    def regularisation(self) -> Regularisation:
        """The FEM's :class:`~granular_material.fem.regularisation.Regularisation`; a value
        it refuses is a SpecError naming the field."""
        try:
            return Regularisation(self.model, self.internal_length)
        except ParameterError as exc:
            field = "model" if exc.field == "regularisation" else exc.field
            raise SpecError(field, exc.message) from None

    def check_element(self, element: str) -> None:
        """SpecError when the run's ``element`` cannot carry the regularisation."""
        if self.model == "second-gradient":
            try:
                check_element_name(element)
            except ParameterError as exc:
                raise SpecError("model", exc.message) from None


@dataclass(frozen=True, kw_only=True)
class OutputSpec:
    """What the run writes and follows.

    Attributes:
        out: the output folder (tables, fields, figures, summary, checkpoint); None: none.
        map_strain: axial strains of the displacement/shear-strain maps and band measures
            (1 to :data:`MAX_MAP_STRAINS`, finite).
        track: Gauss point ids (as text, whole numbers >= 0, none twice; numbers are taken
            as ids) or ("all",) whose RVEs are post-processed; None: none. The run refuses
            more than :data:`MAX_TRACKED_ROWS` post-processings (:meth:`tracked_rows`).
        every: with ``track``: every this many load steps.
        postprocess: with ``track``: the post-processors; None: every installed one.
        checkpoint_every: save the committed state every this many load steps (with out);
            None: by elapsed time (:class:`~granular_material.runs.checkpoint.RunCheckpoint`:
            at most once a second and while saving is cheap, at the latest every
            ``checkpoint_minutes``).
        checkpoint_minutes: with ``checkpoint_every`` None, the longest time [min] between
            two saves of the committed state.
        points_csv: with ``out``, the Gauss-point table also as text, ``points.csv``
            (``points.npy`` is written regardless).
        figures: with ``out``, draw the run's figures at its end (``stress_strain.png``,
            the maps); False: tables, fields and summary only (matplotlib is then not
            imported: about a second of a short run, issue 62).
        progress: show progress bars.
    """

    out: Path | None = None
    map_strain: tuple[float, ...] = (0.02,)
    track: tuple[str, ...] | None = None
    every: int = 1
    postprocess: tuple[str, ...] | None = None
    checkpoint_every: int | None = None
    checkpoint_minutes: float = 10.0
    points_csv: bool = False
    figures: bool = True
    progress: bool = False

    def __post_init__(self) -> None:
        if isinstance(self.track, list | tuple):  # point ids as numbers are ids too
            object.__setattr__(self, "track", tuple(
                str(t) if isinstance(t, int) and not isinstance(t, bool) else t
                for t in self.track))
        _typed(self)
        check_map_strains(self.map_strain)
        if self.track is not None:
            check_track(self.track)
        if self.postprocess is not None:
            check_postprocess(self.postprocess)
        _at_least("every", self.every, 1)
        if self.checkpoint_every is not None:
            _at_least("checkpoint_every", self.checkpoint_every, 1)
        if not (math.isfinite(self.checkpoint_minutes) and self.checkpoint_minutes > 0):
            raise SpecError("checkpoint_minutes",
                            f"must be a time > 0 min, got {self.checkpoint_minutes!r}")

    def tracked_rows(self, n_points: int, steps: int) -> int:
        """The rows tracking computes on ``n_points`` Gauss points over ``steps`` load
        steps: points × post-processors × tracked steps (0 without tracking)."""
        if self.track is None:
            return 0
        points = n_points if "all" in self.track else len(set(self.track))
        return points * len(self.postprocessors()) * (steps // self.every + 1)

    def postprocessors(self) -> tuple[str, ...]:
        """The post-processors of tracked points: the given ones, else every installed one."""
        from granular_material.fem.tracking import available_postprocessors

        return self.postprocess or tuple(available_postprocessors())


#: when a point that meets a threshold becomes DEM: in the step it meets it, or after it
SWITCHES = ("in-step", "after-step")
#: the mobilised fraction of the twin's peak friction angle at which a point switches to its
#: DEM RVE when an [adaptivity] table names no threshold
DEFAULT_MOBILISED_FRACTION = 0.7


@dataclass(frozen=True, kw_only=True)
class AdaptivitySpec:
    """A DEM material modelled only where the run requires it
    (:class:`~granular_material.multiscale.adaptive.AdaptiveMaterial`): every point starts on
    the Mohr–Coulomb twin calibrated from the run's (first) RVE and moves to a DEM RVE of its
    own once a threshold is met: a boundary-value scene's ``[adaptivity]`` table, or a
    specimen's :attr:`RunSpec.adaptivity <granular_material.runs.spec.RunSpec.adaptivity>`.

    Attributes:
        mobilised_fraction: switch once the mobilised friction angle reaches this fraction
            (0, 1] of the twin's peak friction angle; None: not used.
        shear_strain: switch once the accumulated shear strain γ [-] reaches this; None:
            not used (at least one of the two is given).
        neighbours: "element" (every point of a switching point's element switches with it)
            or "point".
        start: how a switching point's RVE starts: "strain" (driven through the point's
            deformation) or "stress" (the stress servo brings it to the point's twin
            stress).
        switch: "in-step" (a point that meets a threshold during a load step is DEM in that
            whole step) or "after-step" (from the next step on).
        calibration: a ``calibration.json`` of ``granular-material calibrate`` whose
            parameters make the twin; None: the scene's RVE (a specimen's first) is
            calibrated at the scene's reference pressure (the specimen's confining pressure)
            when the run starts.
        elastic_window: the axial strain [-] that calibration reads the twin's E and ν over
            (:data:`~granular_material.reference_values.TWIN_ELASTIC_WINDOW`, 2e-4: the
            far field's strains).
    """

    mobilised_fraction: float | None = DEFAULT_MOBILISED_FRACTION
    shear_strain: float | None = None
    neighbours: str = "element"
    start: str = "strain"
    switch: str = "in-step"
    calibration: Path | None = None
    elastic_window: float = TWIN_ELASTIC_WINDOW

    def __post_init__(self) -> None:
        from granular_material.errors import ParameterError

        if self.calibration is not None:
            object.__setattr__(self, "calibration", Path(self.calibration))
        from granular_material.multiscale.switching import check_start

        try:
            self.criterion()
            check_start(self.start)
        except ParameterError as exc:
            raise SpecError(exc.field, exc.message) from None
        if not (isinstance(self.elastic_window, int | float)
                and 0 < self.elastic_window < 0.05):
            raise SpecError("adaptivity.elastic_window", f"must be an axial strain in (0, 0.05) "
                                                         f"[-], got {self.elastic_window!r}")
        if self.calibration is not None and self.elastic_window != TWIN_ELASTIC_WINDOW:
            raise SpecError("adaptivity.elastic_window", "reads the calibration the run makes; "
                                                         "with a calibration file it would do "
                                                         "nothing (give the window to the "
                                                         "calibration that writes the file)")
        if self.switch not in SWITCHES:
            raise SpecError("adaptivity.switch", f"must be one of {', '.join(SWITCHES)}, got "
                                                 f"{self.switch!r}")

    def criterion(self) -> Any:
        """The :class:`~granular_material.multiscale.switching.SwitchCriterion` it names."""
        from granular_material.multiscale.switching import SwitchCriterion

        return SwitchCriterion(self.mobilised_fraction, self.shear_strain, self.neighbours,
                               in_step=self.switch == "in-step")
