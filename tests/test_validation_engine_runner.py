"""The validation's engine runner reads our ``biaxial`` command's options without a process."""

from __future__ import annotations

from granular_material_validation import engine_runner, femxdem_case


def test_biaxial_options_are_read_without_a_process() -> None:
    names = engine_runner.biaxial_option_names()
    assert {"--element", "--convergence", "--formulation", "--rve"} <= names
    assert "--element" in engine_runner.biaxial_options()
    assert set(femxdem_case.ours_variants((1, 2))) == {
        "ours-defaults", "ours-as-gz", "ours-q9", "ours-small-strain", "ours-fine"}
