"""Plan files: the JSON that :class:`planners.plan.Plan` and :class:`planners.tether.plan.TetherPlan` are saved
as, written and read the same way for both; reading, every way it can fail is a typed error with the path.

Each plan type makes and checks its own fields (:mod:`planners.plan.schema`, ``TetherPlan.from_dict``); what
they share is getting between a path and a JSON value, without a traceback from the file system or the parser.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any


def read_plan_json(path: str | Path, error: Callable[[str], Exception], what: str = "plan") -> Any:
    """The JSON value in the file ``path``; any failure raises ``error(message)``, the message naming ``what``
    (``"plan"``, ``"tether plan"``) and the path:

    - the file cannot be read (missing, a folder, no permission): ``cannot read plan p.json: No such file ...``;
    - it nests deeper than Python's parser can follow: ``plan p.json is nested too deeply to be a plan file``;
    - it is not JSON, not UTF-8, or holds an integer of thousands of digits:
      ``plan p.json is not a JSON plan file: <the parser's message, at most 200 characters>``.
    """
    try:
        return json.loads(Path(path).read_bytes())
    except OSError as exc:
        raise error(f"cannot read {what} {path}: {exc.strerror or exc}") from None
    except RecursionError:
        raise error(f"{what} {path} is nested too deeply to be a {what} file") from None
    except ValueError as exc:  # JSONDecodeError, UnicodeDecodeError, an integer of thousands of digits
        raise error(f"{what} {path} is not a JSON {what} file: {str(exc)[:200]}") from None


def write_plan_json(path: str | Path, data: Any, indent: int) -> Path:
    """Write ``data`` as JSON to ``path`` (its folders created), indented by ``indent``, atomically
    (:func:`impact_env.results_store.write_atomic`); returns the path."""
    from impact_env.results_store import write_atomic

    return write_atomic(path, json.dumps(data, indent=indent))
