"""Studies built on the runs and their results: the speed/accuracy trade study
(:mod:`granular_material.studies.trade`)."""

from granular_material.studies.trade import SCALES, Knob, StudyScale, plan_runs, run_trade_study

__all__ = ["SCALES", "Knob", "StudyScale", "plan_runs", "run_trade_study"]
