"""Where :class:`RunContext` was: it lives beside the ``Material`` protocol now
(:mod:`granular_material.fem.materials.run_context`); imported from here too, and from
:mod:`granular_material.runs`."""

from granular_material.fem.materials.run_context import RunContext

__all__ = ["RunContext"]
