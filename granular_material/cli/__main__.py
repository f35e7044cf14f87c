"""``python -m granular_material.cli``: the command line."""

from granular_material.cli import entry

entry()
