"""The boundary-value API refuses misuse with a SpecError naming the field, not a TypeError or
an AttributeError from deep inside (issue 61, kind 9)."""

from __future__ import annotations

import pytest

from granular_material.runs.boundary_value.spec import (
    BoundaryValueSpec,
    ConditionSpec,
    MeshSpec,
    bvp_from_dict,
)
from granular_material.runs.spec import SpecError

MESH = MeshSpec(size=(0.4, 0.2), elements=(2, 2))
FIXED = ConditionSpec(type="fixed", boundary="bottom")


@pytest.mark.parametrize("data", [None, [1, 2], "test = 'boundary-value'", 3, b"x", (1,)],
                         ids=["None", "list", "text", "int", "bytes", "tuple"])
def test_bvp_from_dict_refuses_what_is_no_table(data):
    with pytest.raises(SpecError) as refused:
        bvp_from_dict(data)
    assert refused.value.field == "scene"


@pytest.mark.parametrize("fields, field", [
    ({"mesh": {"size": [0.4, 0.2], "elements": [2, 2]}}, "mesh"),
    ({"mesh": None}, "mesh"),
    ({"initial": {"state": "uniform", "pressure": 1e5}}, "initial"),
    ({"material": {"name": "linear-elastic"}}, "material"),
    ({"newton": {"rtol": 1e-6}}, "newton"),
    ({"boundaries": ["footing"]}, "boundaries"),
    ({"boundaries": {"footing": 3}}, "boundaries"),
    ({"conditions": ({"type": "fixed", "boundary": "bottom"},)}, "conditions"),
    ({"conditions": [{"type": "fixed", "boundary": "bottom"}]}, "conditions"),
    ({"conditions": {"type": "fixed", "boundary": "bottom"}}, "conditions"),
    ({"conditions": "fixed"}, "conditions"),
    ({"conditions": 3}, "conditions"),
    ({"conditions": (FIXED, "roller")}, "conditions"),
])
def test_a_spec_given_tables_for_its_sections_is_refused_naming_them(fields, field):
    given = {"mesh": MESH, "conditions": (FIXED,), **fields}
    with pytest.raises(SpecError) as refused:
        BoundaryValueSpec(**given)
    assert refused.value.field == field


def test_a_list_of_conditions_is_kept_as_a_tuple():
    spec = BoundaryValueSpec(mesh=MESH, conditions=[FIXED])
    assert spec.conditions == (FIXED,)
