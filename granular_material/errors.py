"""The one error type of a parameter that cannot be used: it carries the field it names.

The library raises :class:`ParameterError` with the field's own name (``tangent``,
``max_strain_per_step``); whoever shows it to a user names the field their way: the run
specification keeps the name (its :class:`~granular_material.runs.spec.SpecError` is one),
the command line turns it into the option of the same name (``--max-strain-per-step``) in one
place. Nobody recovers a field's name from a message's text.
"""

from __future__ import annotations

__all__ = ["ParameterError"]


class ParameterError(ValueError):
    """A value that cannot be used; ``field`` is its name, ``message`` what is wrong.

    ``str(error)`` is ``"<field> <message>"``, e.g. ``"tangent must be one of ..."``.
    """

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field} {message}")
        self.field = field
        self.message = message
