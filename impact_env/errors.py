"""Typed errors of impact_env: the contract for bad input.

Every error a user can provoke with bad input (a scenario file, an STL text, an action, an environment
option, a controller name, a model folder) is one of the classes below, with a message that names the
offending field, token or file and says what would be accepted instead. Nothing else escapes on purpose:
no ``KeyError`` from a lookup, no ``RecursionError`` from a parser, no ``ZeroDivisionError`` from a
degenerate polygon. The planners add theirs in ``planners/errors.py`` (all subclasses of
:class:`ImpactEnvError`, listed in ``planners.errors.PLANNER_ERRORS``).

:data:`TYPED_ERRORS` lists this package's classes. The property-based tests (``tests/fuzz/``) accept
exactly these and the planners' as the outcome of a bad input, and ``tests/impact_env/test_errors_contract.py`` checks
that every exception class the packages define is listed here or there.
"""

from __future__ import annotations


class ImpactEnvError(Exception):
    """Base class of every error raised on purpose by impact_env (and by planners/ and baselines/)."""


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


class STLUnsupportedError(STLError):
    """A valid STL formula that an evaluator does not support (e.g. nested temporal operators in the batched
    world's monitor); the message names the subformula and what would be accepted."""


class ActionError(ImpactEnvError, ValueError):
    """An action has the wrong type or shape, or contains NaN / infinite values."""


class EnvConfigError(ImpactEnvError, ValueError):
    """An environment option is out of range or of the wrong kind."""


class ControllerError(ImpactEnvError, ValueError):
    """An unknown controller name, or a controller that could not be built."""


class TetherError(ImpactEnvError, ValueError):
    """A tether command that the world cannot carry out (unknown anchor, robot already pulling, ...)."""


class HyperparameterError(ImpactEnvError, ValueError):
    """A hyperparameter file (``baselines/hyperparams/*.yml``) or one of its entries is malformed."""


class ModelFileError(ImpactEnvError, ValueError):
    """A saved model folder (model.zip, train.json, normalisation statistics) is missing, malformed or does
    not fit the scenario; names the file."""


class UntrustedFileError(ModelFileError):
    """A file could run code when loaded (a pickle, or a model zip's pickled entries) and was not trusted.

    The message names the file and the option that would trust it (``--trust-pickle``); trust only files
    you made yourself.
    """


class EngineError(ImpactEnvError, RuntimeError):
    """An execution engine (``--engine local|ray`` for sweeps, ``--engine rllib`` for training) cannot run: Ray
    is not installed, the cluster at ``--address`` cannot be reached, a job failed on a worker, or an engine
    option is out of range. The message says which, and what to install or start."""


class ResultsFileError(ImpactEnvError, ValueError):
    """A results file (a benchmark's ``cells.jsonl``, :mod:`impact_env.results_store`) has a line that is not
    a complete cell: names the file and line, and what to do (usually: delete the line, rerun its cell)."""


class OutputPathError(ImpactEnvError, OSError):
    """An output path cannot be written: a folder where a file is asked for (or a file where a folder is), a
    device such as ``/dev/full``, a path under ``/proc``, a folder without write permission, a full disk. Names
    the path (and the option that gave it) and the reason. The commands check their output paths before any
    work starts (:func:`impact_env.results_store.check_output_file`), so a run is not lost at its end. An
    ``OSError`` too, so code that caught the file system's errors still catches it."""


class GeneratedTaskError(ScenarioError):
    """A generated task (:mod:`impact_env.transport.generate`) breaks one of its rules (names the body or region
    and the rule), its family or seed is not one the generator knows, or no draw met the placement rules."""


TYPED_ERRORS: tuple[type[ImpactEnvError], ...] = (
    ImpactEnvError, ScenarioError, STLError, STLSyntaxError, STLBindingError, STLUnsupportedError, ActionError,
    EnvConfigError, ControllerError, TetherError, HyperparameterError, ModelFileError, UntrustedFileError, EngineError,
    ResultsFileError, OutputPathError, GeneratedTaskError,
)


def brief(value: object, width: int = 60) -> str:
    """``value`` as an error message quotes it: its repr, cut to ``width`` characters (``...`` at the end).

    A value whose repr fails or recurses (an integer of thousands of digits, a list nested thousands deep)
    is named by its type instead, so that building the message never raises.
    """
    try:
        text = repr(value)
    except (ValueError, RecursionError):
        return f"a {type(value).__name__}"
    return text if len(text) <= width else text[:width - 3] + "..."
