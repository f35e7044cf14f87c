"""The Newton settings the commands use: the one source of their defaults.

:class:`~granular_material.fem.NewtonSettings` itself defaults to plain Newton (tangent
predictor, no relaxation, no stall acceptance), the textbook method a library caller
starts from. The commands ask :func:`default_settings` for the settings of a material (by whether
its stress is noisy: a material class's ``noisy`` attribute, True for DEM RVEs), so what
``--help`` shows and what a run does come from here.
"""

from __future__ import annotations

from typing import Any

from granular_material.fem.materials.protocol import load_material
from granular_material.fem.solver.newton import NewtonSettings

__all__ = ["COMMAND_DEFAULTS", "NOISY_DEFAULTS", "SMOOTH_DEFAULTS", "default_settings",
           "default_stress_tol", "is_noisy"]

#: what the commands change from NewtonSettings' own defaults, for every material: Guo &
#: Zhao's FEM×DEM solve() — finite strain in the updated-Lagrangian form, plain Newton steps
#: (no relaxation), accepted once the correction is within 1e-2 of the step's displacement,
#: up to 100 iterations — with the last increment extrapolated as the predictor (their code
#: solves with the committed tangent: the same band, half the iterations). On their 2 × 4
#: case this is a loop in which the shear band of their code forms; with Aitken relaxation
#: and the objective tangent it stays nearly uniform, whatever the test (see
#: docs/physics-tangents.md, "Finite strain and the band"), so Aitken comes only with the
#: noisy defaults below.
#: The test is theirs judged one iterate earlier ("residual-displacement"): the iterate
#: whose correction is within 1e-2 is accepted, where their loop applies that correction
#: and evaluates the RVEs once more (issue 26: a DEM run less per increment, a fifth fewer
#: particle-steps; docs/physics.md, "Newton convergence")
COMMAND_DEFAULTS: dict[str, Any] = {"formulation": "updated-lagrangian",
                                    "convergence": "residual-displacement", "rtol": 1e-2,
                                    "predictor": "extrapolate", "max_iterations": 100}

#: what a noisy (DEM) material's commands add, with the condensed tangent the DEM commands
#: default to (issue 26; condensed-sticking since it reached 10 % with plain Newton too): the
#: tangent of an increment's first evaluation held for all its
#: corrections (it cannot cycle between sliding sets, and the RVEs condense once an
#: increment) and Aitken relaxation (it damps the DEM noise a soft tangent turns into
#: displacement). On Guo & Zhao's 2 × 4 case their band still forms, no later than with the
#: objective tangent, at about a quarter fewer particle-steps; see docs/physics-tangents.md,
#: "A held tangent". A smooth material keeps full Newton: plain steps, the tangent of every iterate.
NOISY_DEFAULTS: dict[str, Any] = {"relaxation": "aitken", "tangent_update": "hold"}

#: what a material whose stress carries no noise (linear-elastic, Mohr–Coulomb) changes: its
#: equilibrium is judged by the force residual itself, to 1e-4 of the step's initial one.
#: The displacement tests never look at the residual; they stand in for it where DEM noise
#: keeps ‖R‖ from falling, and with the apex's zero tangent they let a softening
#: Mohr–Coulomb footing through with ‖R‖/‖R₀‖ up to 4.4. 1e-2 of R₀ is too loose where R₀ is
#: the kick of a moved boundary: Guo & Zhao's passive wall took a step on its extrapolated
#: predictor with the soil beside it 45 % above Rankine's limit (at 1e-4: 0.983 × Rankine,
#: 2.2 iterations a step; at 1e-6 the apex's floored tangent costs 22 iterations a step)
SMOOTH_DEFAULTS: dict[str, Any] = {"convergence": "force", "rtol": 1e-4}

#: a noisy material's increment whose force residual stalls is accepted once the Newton
#: correction is this small (Guo & Zhao's ‖δu‖/‖Δu‖ test and tolerance)
NOISY_ACCEPT_CORRECTION = 1e-2



def is_noisy(material: str | bool) -> bool:
    """Whether the stress of ``material`` (an entry-point name, or the answer itself) carries
    noise: its class says so with ``noisy = True`` (DEM RVEs); such a material gets a stall
    tolerance and an absolute stress tolerance by default."""
    if isinstance(material, bool):
        return material
    return bool(getattr(load_material(material), "noisy", False))


def default_settings(material: str | bool, **overrides: Any) -> NewtonSettings:
    """The Newton settings of the commands for ``material`` (a name, or whether it is noisy:
    :func:`is_noisy`).

    ``overrides`` are NewtonSettings fields; one given as None takes its default. A noisy
    (DEM) material gets :data:`NOISY_DEFAULTS` (Aitken relaxation, the tangent held over an
    increment; no relaxation with secant updates unless one is asked for), any other
    :data:`SMOOTH_DEFAULTS` (the force test to 1e-4); the stall
    tolerance defaults to 2 × rtol for it and to 0 (off) otherwise; so does the acceptance
    of a stalled residual on a small correction (:data:`NOISY_ACCEPT_CORRECTION`).
    """
    noisy = is_noisy(material)
    values = dict(COMMAND_DEFAULTS)
    if noisy:
        values.update(NOISY_DEFAULTS)
        if overrides.get("tangent_update") == "secant" and overrides.get("relaxation") is None:
            # Broyden updates and Aitken fight (docs/physics-tangents.md)
            values["relaxation"] = "none"
    else:
        values.update(SMOOTH_DEFAULTS)
    values.update({k: v for k, v in overrides.items() if v is not None})
    if "stall_rtol" not in values:
        rtol = values.get("rtol", NewtonSettings.rtol)
        values["stall_rtol"] = 2 * rtol if noisy else 0.0
    if "accept_correction" not in values:
        values["accept_correction"] = NOISY_ACCEPT_CORRECTION if noisy else 0.0
    return NewtonSettings(**values)


def default_stress_tol(material: str | bool, confining: float) -> float:
    """Absolute Newton tolerance as a stress error [Pa] (``run_biaxial(stress_tol=...)``).

    Wu et al.'s 0.005, taken of the confining stress, for a noisy (DEM) material: the floor
    below which DEM stress noise stalls Newton once a step's own load is small; 0 otherwise.
    """
    return 5e-3 * confining if is_noisy(material) else 0.0
