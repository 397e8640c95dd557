"""Actions that are numpy arrays but not plain ones: a masked array, a matrix (issue 24: a masked-NaN action on
the Gymnasium transport env gave a ``TypeError`` from deep inside the core)."""

from __future__ import annotations

import numpy as np
import pytest

import impact_env
from impact_env.envs import TetherEnv, TransportEnv
from impact_env.errors import ActionError


@pytest.fixture
def env():
    env = TransportEnv("corridor")
    env.reset(seed=0)
    return env


@pytest.mark.parametrize("action", [
    np.ma.masked_invalid(np.array([np.nan, 0, 0, 0, 0, 0], dtype=np.float32)),
    np.ma.masked_invalid(np.array([[np.nan, 0, 0], [0, 0, 0]])),
    np.ma.array(np.zeros(6), mask=[0, 0, 1, 0, 0, 0]),
    np.ma.masked_all((6,)),
])
def test_masked_entries_are_an_action_error(env, action):
    with pytest.raises(ActionError, match="masked array"):
        env.step(action)


@pytest.mark.parametrize("action", [np.ma.array(np.full(6, 0.5), mask=False), np.matrix(np.full((2, 3), 0.5)),
                                    np.ma.array(np.full((2, 3), 0.5, dtype=np.float32))])
def test_unmasked_and_matrix_actions_act_as_their_numbers(env, action):
    other = TransportEnv("corridor")
    other.reset(seed=0)
    obs, reward, *_ = env.step(action)
    expected, expected_reward, *_ = other.step(np.full(6, 0.5))
    np.testing.assert_array_equal(obs, expected)
    assert reward == expected_reward


def test_masked_nan_on_the_pettingzoo_env():
    par = impact_env.parallel_env(scenario="corridor")
    par.reset(seed=0)
    with pytest.raises(ActionError, match=r"actions\['R1'\] is a masked array"):
        par.step({"R1": np.ma.masked_invalid(np.array([np.nan, 0.0, 0.0]))})


def test_masked_tether_actions_are_action_errors():
    env = TetherEnv("L")
    env.reset(seed=0)
    with pytest.raises(ActionError):
        env.step(np.ma.masked_all(env.action_space.shape, dtype=np.int64))


def test_the_compiled_loop_does_not_read_under_the_mask(env):
    """The compiled substep loop reads an array's buffer, mask or not: masked actions take the checked path,
    also as rows of a list and as PettingZoo actions."""
    from impact_env.transport import native

    if not native.available():
        pytest.skip("the compiled substep loop is not built")
    with pytest.raises(ActionError, match="masked array with 1 masked entries"):
        env.step([np.ma.array(np.zeros(3), mask=[0, 1, 0]), np.zeros(3)])
    par = impact_env.parallel_env(scenario="corridor")
    par.reset(seed=0)
    with pytest.raises(ActionError, match=r"actions\['R2'\] is a masked array"):
        par.step({"R1": np.zeros(3), "R2": np.ma.masked_all((3,))})
    obs, *_ = env.step([np.ma.array(np.ones(3) * 0.5), np.zeros(3)])  # nothing masked: its numbers
    assert np.all(np.isfinite(obs))
