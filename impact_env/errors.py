"""Typed errors of impact_env.

Every error a user can provoke with bad input is one of these, with a message that names the offending
field or token and says what would be accepted instead.
"""

from __future__ import annotations


class ImpactEnvError(Exception):
    """Base class of every error raised on purpose by impact_env."""


class ScenarioError(ImpactEnvError, ValueError):
    """A scenario file or Scenario object is malformed: names the field path and the reason."""


class STLError(ImpactEnvError, ValueError):
    """Base class of errors about STL formulas."""


class STLSyntaxError(STLError):
    """An STL formula text could not be parsed; the message points at the column."""

    def __init__(self, message: str, text: str = "", column: int | None = None) -> None:
        if column is not None and text:
            message = f"{message}\n  {text}\n  {' ' * column}^ (column {column})"
        super().__init__(message)
        self.text = text
        self.column = column


class STLBindingError(STLError, KeyError):
    """A formula names a body or region that the trace or scenario does not have."""

    def __str__(self) -> str:  # KeyError would repr() the message
        return str(self.args[0]) if self.args else ""


class ActionError(ImpactEnvError, ValueError):
    """An action has the wrong shape or contains NaN / infinite values."""
