"""Which run folders hold a run that has ended, and which can continue
(granular_material.runs.run_folder)."""

from __future__ import annotations

import json

from granular_material.runs.run_folder import ended_summary, interrupted_error, resumable


def test_ended_and_interrupted_runs_are_told_apart(tmp_path):
    assert ended_summary(tmp_path) is None and not resumable(tmp_path)
    for error, ended in ((None, True), ("load step 3 did not converge", True),
                         (interrupted_error(2, 5), False)):
        (tmp_path / "summary.json").write_text(json.dumps({"error": error}))
        assert (ended_summary(tmp_path) is not None) is ended
    assert interrupted_error(2, 5) == "interrupted after load step 2 of 5"
    (tmp_path / "checkpoint").mkdir()
    assert not resumable(tmp_path)  # a folder without the run's record
    (tmp_path / "checkpoint" / "options.json").write_text("{}")
    assert resumable(tmp_path)
