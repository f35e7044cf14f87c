"""The Newton settings the commands use: the one source of their defaults.

:class:`~granular_material.fem.NewtonSettings` itself defaults to plain Newton (tangent
predictor, no relaxation, no stall acceptance), the textbook method a library caller
starts from. The commands ask :func:`default_settings` for the settings of a material by
name, so what ``--help`` shows and what a run does come from here.
"""

from __future__ import annotations

from typing import Any

from granular_material.fem.newton import NewtonSettings

__all__ = ["DEM_REUSE_TOL", "NOISY_MATERIALS", "default_settings", "default_stress_tol"]

#: materials whose stress carries noise (DEM RVEs): they get a stall tolerance and an
#: absolute stress tolerance by default
NOISY_MATERIALS = frozenset({"dem"})

#: what the commands change from NewtonSettings' own defaults, for every material: Guo &
#: Zhao's FEM×DEM solve() — finite strain in the updated-Lagrangian form, plain Newton steps
#: (no relaxation), accepted once the correction is within 1e-2 of the step's displacement,
#: up to 100 iterations — with the last increment extrapolated as the predictor (their code
#: solves with the committed tangent: the same band, half the iterations). On their 2 × 4
#: case this is a loop in which the shear band of their code forms; with Aitken relaxation
#: it stays nearly uniform, whatever the test (see the README, "Finite strain")
COMMAND_DEFAULTS: dict[str, Any] = {"formulation": "updated-lagrangian",
                                    "convergence": "displacement", "rtol": 1e-2,
                                    "predictor": "extrapolate", "relaxation": "none",
                                    "max_iterations": 100}

#: a noisy material's increment whose force residual stalls is accepted once the Newton
#: correction is this small (Guo & Zhao's ‖δu‖/‖Δu‖ test and tolerance)
NOISY_ACCEPT_CORRECTION = 1e-2

#: the commands' reuse tolerance of the DEM material [-]: an RVE whose ∇u moved by at most
#: this since it was last driven keeps its response (see the README's measurements)
DEM_REUSE_TOL = 0.0


def default_settings(material: str, **overrides: Any) -> NewtonSettings:
    """The Newton settings of the commands for the material named ``material``.

    ``overrides`` are NewtonSettings fields; one given as None takes its default. The stall
    tolerance defaults to 2 × rtol for a noisy (DEM) material and to 0 (off) otherwise; so
    does the acceptance of a stalled residual on a small correction
    (:data:`NOISY_ACCEPT_CORRECTION`).
    """
    values = dict(COMMAND_DEFAULTS)
    values.update({k: v for k, v in overrides.items() if v is not None})
    if "stall_rtol" not in values:
        rtol = values.get("rtol", NewtonSettings.rtol)
        values["stall_rtol"] = 2 * rtol if material in NOISY_MATERIALS else 0.0
    if "accept_correction" not in values:
        values["accept_correction"] = (NOISY_ACCEPT_CORRECTION if material in NOISY_MATERIALS
                                       else 0.0)
    return NewtonSettings(**values)


def default_stress_tol(material: str, confining: float) -> float:
    """Absolute Newton tolerance as a stress error [Pa] (``run_biaxial(stress_tol=...)``).

    Wu et al.'s 0.005, taken of the confining stress, for a noisy (DEM) material: the floor
    below which DEM stress noise stalls Newton once a step's own load is small; 0 otherwise.
    """
    return 5e-3 * confining if material in NOISY_MATERIALS else 0.0
