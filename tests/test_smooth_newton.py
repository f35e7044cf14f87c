"""A smooth material's Newton steps end in equilibrium: the commands' default convergence
test for linear-elastic and Mohr–Coulomb is the force residual, to 1e-4 (fem/solver/defaults.py).

The case is the one that showed the need: Guo & Zhao's reduced footing with the Mohr–Coulomb
twin calibrated from their RVE at 20 kPa (φ 35.8° softening to 22.4° over γp = 0.043),
small strain. The displacement test (Guo & Zhao's, judged one iterate early) never looks at
the residual: with the apex's exact (zero) tangent it accepted steps after one iteration
with ‖R‖/‖R₀‖ up to 4.4 and 645 kPa at 6 mm, where the force test gives 279 kPa; with the
apex's floored tangent (the default) it still leaves ‖R‖/‖R₀‖ = 0.03 on this case.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10
    import tomli as tomllib

from granular_material.runs.boundary_value.runner import run_boundary_value
from granular_material.runs.boundary_value.spec import bvp_from_dict

SCENE = Path(__file__).resolve().parents[1] / "examples" / "scenes" / "footing-gz2016-cpu.toml"
#: the twin calibrated from the footing's RVE (docs/validation/mohr-coulomb, "gz20k")
TWIN = {"young": 19.04e6, "poisson": 0.2543, "friction_angle": 35.81, "dilation_angle": 16.78,
        "critical_friction_angle": 22.35,
        "softening_strain": 0.04347}
STEPS = 24  # 6 mm of the scene's 0.25 mm steps


def _footing(convergence: str | None) -> dict:
    data = tomllib.loads(SCENE.read_text(encoding="utf-8"))
    data["steps"] = STEPS
    for c in data["conditions"]:
        if c["type"] == "rigid":
            c["displacement"] = [0.0, -0.25e-3 * STEPS]
    data["material"] = {"name": "mohr-coulomb", "parameters": TWIN}
    data["newton"] = {"formulation": "small-strain"}
    if convergence is not None:
        data["newton"]["convergence"] = convergence
    data["output"] = {"fields": False, "progress": False}
    return data


def _final_ratios(steps) -> list[float]:
    """‖R‖/‖R₀‖ of each step's accepted iterate (the last of its last attempt)."""
    out = []
    for history in steps["residual_history"].iloc[1:]:
        attempts = json.loads(history) if isinstance(history, str) else history
        out.append(attempts[-1][-1])
    return out


def test_a_smooth_material_is_accepted_in_equilibrium_by_default():
    spec = bvp_from_dict(_footing(None), SCENE.parent)
    assert spec.newton.convergence_test(spec.material.noisy) == "force"
    outcome = run_boundary_value(spec, out=None)
    assert outcome.error is None
    ratios = _final_ratios(outcome.steps)
    assert len(ratios) == STEPS
    assert max(ratios) <= 1e-4  # the force test's rtol: every step in equilibrium
