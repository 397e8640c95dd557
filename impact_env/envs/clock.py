"""The episode's clock on every environment: ``dt_s``, ``horizon_steps`` and ``horizon_s``.

All four environment classes (Gymnasium and PettingZoo, impact and tether) hold a core with ``dt_s`` (the
control period) and ``horizon_steps`` (the STL task's horizon in steps, where the episode terminates). A
Gymnasium wrapper does not forward attributes, so read them as ``env.unwrapped.dt_s``.
"""

from __future__ import annotations

import inspect
from typing import Any

from impact_env.errors import EnvConfigError

# keywords users reach for that have another name here (the CLI's old option names among them)
_OTHER_NAMES = {"reward": "reward_mode", "init_noise": "initial_position_noise_m",
                "initial_noise": "initial_position_noise_m", "position_noise": "initial_position_noise_m",
                "e": "restitution", "map": "station", "scenario_name": "scenario"}


class EpisodeClock:
    """Mixin: the episode's control period and horizon, read from ``self.core``."""

    core: Any

    @property
    def dt_s(self) -> float:
        """Simulated time per step (s): the scenario's or station's ``control_period_s``."""
        return self.core.dt_s

    @property
    def horizon_steps(self) -> int:
        """Steps per episode: the task's horizon, where ``terminated`` becomes True."""
        return self.core.horizon_steps

    @property
    def horizon_s(self) -> float:
        """Simulated length of an episode (s): ``horizon_steps * dt_s``."""
        return self.core.horizon_steps * self.core.dt_s


def required(value: Any, name: str, what: str, example: str) -> Any:
    """``value`` unless it is None: an environment without its scenario or station is an error, not a default."""
    if value is None:
        raise EnvConfigError(f"{name}= is required: {what}; e.g. {example}")
    return value


def check_render_options(metadata: dict, render_mode: str | None, render_width_px: int) -> None:
    if render_mode is not None and render_mode not in metadata["render_modes"]:
        raise EnvConfigError(f"render_mode must be one of {metadata['render_modes']} or None, got {render_mode!r}")
    if not (type(render_width_px) is int and 16 <= render_width_px <= 8192):
        raise EnvConfigError(f"render_width_px must be an integer in 16..8192, got {render_width_px!r}")


def check_max_cycles(max_cycles: int | None) -> None:
    if max_cycles is not None and not (type(max_cycles) is int and max_cycles >= 1):
        raise EnvConfigError(f"max_cycles must be a positive integer or None, got {max_cycles!r}")


def reject_unknown(unknown: dict[str, Any], cls: type) -> None:
    """An unknown keyword is a typed error naming the right one (``reward=`` -> ``reward_mode``), not a default."""
    if not unknown:
        return
    from impact_env.names import suggestion

    names = [p.name for p in inspect.signature(cls.__init__).parameters.values()
             if p.name != "self" and p.kind is not p.VAR_KEYWORD]
    parts = []
    for key in unknown:
        hint = f" (did you mean {_OTHER_NAMES[key]!r}?)" if _OTHER_NAMES.get(key) in names else \
            suggestion(key, names, cutoff=0.5)
        parts.append(f"{key!r}{hint}")
    raise EnvConfigError(f"{cls.__name__} has no argument {', '.join(parts)}; its arguments are {', '.join(names)}")
