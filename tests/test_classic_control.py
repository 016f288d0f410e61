"""Tile-coding defaults for Gymnasium's classic control (issue 12): the generic rule, sb3-er's tilings for known env
ids, their precedence, the verbose print and the zoo entries (that every algorithm's defaults learn: test_learning.py).

Expected widths are computed here from the envs' own constants (bounds, termination thresholds) and the sources'
recipes, not read back from the package data.
"""

from pathlib import Path
from typing import ClassVar

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.envs.classic_control import CartPoleEnv
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import SubprocVecEnv

from sb3_er import ER, ERSigma, SarsaLambda, zoo
from sb3_er.common.tile_coding import (
    default_tile_widths,
    default_tiles_per_dimension,
    package_tilings,
)

CLASSIC_IDS = ("CartPole-v1", "MountainCar-v0", "Acrobot-v1")
SMALL = {"memory_size": 2**16}


def widths_of(model):
    return model.policy.tile_coder.tile_widths.tolist()


# --- the generic rule: min(10, floor(budget^(1/D))), at least 2 ------------------------------------------------------


@pytest.mark.parametrize(
    "n_dims, budget, expected",
    [
        (1, 2**14, 10),  # 16384 > 10: capped at 10
        (2, 2**14, 10),  # sqrt(16384) = 128
        (4, 2**14, 10),  # 16384^(1/4) = 11.3
        (5, 2**14, 6),  # 6^5 = 7776 <= 16384 < 7^5 = 16807
        (6, 2**14, 5),  # 5^6 = 15625 <= 16384 < 6^6 = 46656
        (7, 2**14, 4),  # 4^7 = 16384 exactly (the float root gives 3.99999...)
        (8, 2**14, 3),  # 3^8 = 6561 <= 16384 < 4^8 = 65536
        (14, 2**14, 2),  # 2^14 exactly
        (20, 2**14, 2),  # 16384^(1/20) = 1.6: at least 2
        (6, 15625, 5),  # 5^6 exactly (the float root gives 4.99999...)
        (6, 15624, 4),
        (3, 8, 2),
    ],
)
def test_tiles_per_dimension_rule_by_hand(n_dims, budget, expected):
    assert default_tiles_per_dimension(n_dims, budget) == expected


def test_generic_widths_of_a_six_dimensional_box_by_hand():
    low = np.array([-1, -1, -1, -1, -4 * np.pi, -9 * np.pi])
    space = spaces.Box(low, -low, dtype=np.float64)
    # 6 dimensions -> 5 tiles each: 2/5 for the unit ranges, 8 pi / 5 and 18 pi / 5 for the others
    assert default_tile_widths(space) == pytest.approx([0.4] * 4 + [8 * np.pi / 5, 18 * np.pi / 5])
    assert default_tile_widths(space, tiles_per_dimension=10) == pytest.approx([0.2] * 4 + [0.8 * np.pi, 1.8 * np.pi])


def test_constant_dimensions_do_not_count_in_the_budget():
    low = np.array([0.0] * 6 + [3.0])
    high = np.array([1.0] * 6 + [3.0])
    assert default_tile_widths(spaces.Box(low, high, dtype=np.float64)) == pytest.approx([0.2] * 6 + [1.0])


# --- sb3-er's tilings for the classic-control ids ------------------------------------------------------------------


def test_package_data_is_declared_for_the_wheel():
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    pyproject = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text())
    assert "sb3_er.data" in pyproject["tool"]["setuptools"]["packages"]
    assert "*.yml" in pyproject["tool"]["setuptools"]["package-data"]["sb3_er.data"]


@pytest.mark.parametrize("env_id", CLASSIC_IDS)
def test_each_entry_fits_its_env_and_names_its_source(env_id):
    entry = package_tilings()[env_id]
    env = gym.make(env_id)
    assert tuple(entry["observation_shape"]) == env.observation_space.shape
    assert isinstance(env.action_space, spaces.Discrete)
    assert len(entry["tile_widths"]) == env.observation_space.shape[0]
    assert entry["source"]


def test_mountain_car_is_sutton_and_bartos_grid_refined_to_16_tilings_of_10_by_10():
    env = gym.make("MountainCar-v0")
    model = SarsaLambda("TileQ", "MountainCar-v0")
    span = env.observation_space.high - env.observation_space.low  # position 1.8, velocity 0.14
    assert widths_of(model) == pytest.approx(span / 10)
    assert model.policy.tile_coder.n_tilings == 16


def test_acrobot_follows_sutton_1996():
    env = gym.make("Acrobot-v1").unwrapped
    model = SarsaLambda("TileQ", "Acrobot-v1")
    velocities = [2 * env.MAX_VEL_1 / 6, 2 * env.MAX_VEL_2 / 6]  # 6 intervals over his velocity limits
    assert widths_of(model) == pytest.approx([2 / 3] * 4 + velocities)  # cos, sin: 3 intervals of [-1, 1]
    assert model.policy.tile_coder.n_tilings == 32


def test_cart_pole_is_the_measured_tiling():
    model = ERSigma("TileQ", "CartPole-v1")
    assert widths_of(model) == [0.5, 0.5, 0.05, 0.5]
    assert model.policy.tile_coder.n_tilings == 16


@pytest.mark.parametrize(
    "make_env",
    [
        lambda: "Acrobot-v1",
        lambda: gym.wrappers.RecordEpisodeStatistics(gym.make("Acrobot-v1")),
        lambda: make_vec_env("Acrobot-v1"),
    ],
    ids=["id", "gymnasium-wrapper", "vec-env"],
)
def test_the_id_is_found_through_wrappers_and_vec_envs(make_env):
    model = ER("TileQ", make_env(), policy_kwargs=SMALL)
    assert widths_of(model) == pytest.approx(package_tilings()["Acrobot-v1"]["tile_widths"])


def test_the_id_is_found_in_a_subproc_vec_env():
    env = SubprocVecEnv([lambda: gym.make("CartPole-v1")])
    try:
        model = SarsaLambda("TileQ", env, policy_kwargs=SMALL)
        assert widths_of(model) == pytest.approx(package_tilings()["CartPole-v1"]["tile_widths"])
    finally:
        env.close()


class WithTileWidths(gym.Wrapper):
    """CartPole carrying its own ``tile_widths`` attribute, as sb3-er's envs do."""

    tile_widths: ClassVar[list[float]] = [1.0, 2.0, 0.1, 2.0]


def test_precedence_policy_kwargs_then_env_then_package_then_generic():
    explicit = SarsaLambda("TileQ", "CartPole-v1", policy_kwargs=dict(tile_widths=[1, 1, 0.1, 1], **SMALL))
    assert widths_of(explicit) == [1, 1, 0.1, 1]
    assert explicit.policy.tile_coder.n_tilings == 16  # the package's tiling is one unit: not mixed with other widths
    from_env = SarsaLambda("TileQ", WithTileWidths(gym.make("CartPole-v1")), policy_kwargs=SMALL)
    assert widths_of(from_env) == WithTileWidths.tile_widths
    fewer = SarsaLambda("TileQ", "Acrobot-v1", policy_kwargs=dict(n_tilings=4, **SMALL))
    assert fewer.policy.tile_coder.n_tilings == 4
    assert widths_of(fewer) == pytest.approx(package_tilings()["Acrobot-v1"]["tile_widths"])
    counted = SarsaLambda("TileQ", "MountainCar-v0", policy_kwargs=dict(tiles_per_dimension=4, **SMALL))
    assert widths_of(counted) == pytest.approx([1.8 / 4, 0.14 / 4]) and counted.policy.tile_coder.n_tilings == 16


def test_explicit_tiles_per_dimension_beats_the_envs_widths():
    model = SarsaLambda("TileQ", WithTileWidths(gym.make("MountainCar-v0")), policy_kwargs={"tiles_per_dimension": 2})
    assert widths_of(model) == pytest.approx([1.8 / 2, 0.14 / 2])


def test_another_observation_shape_falls_back_to_the_generic_rule(capsys):
    env = gym.wrappers.TransformObservation(gym.make("Acrobot-v1"), lambda obs: obs[:4], spaces.Box(-1.0, 1.0, (4,)))
    model = SarsaLambda("TileQ", env, policy_kwargs=SMALL, verbose=1)
    assert widths_of(model) == pytest.approx([0.2] * 4)  # 4 dimensions: 10 tiles of [-1, 1]
    assert "is for observations of shape (6,), not (4,): not used" in capsys.readouterr().out


def test_an_env_without_an_id_gets_no_package_tiling():
    with pytest.raises(ValueError, match=r"dimensions \[1, 3\] are unbounded"):
        SarsaLambda("TileQ", CartPoleEnv())


class UnitBoxEnv(gym.Env):
    """Observations in [0, 1]^6, two actions, no env id."""

    observation_space = spaces.Box(np.zeros(6), np.ones(6), dtype=np.float64)
    action_space = spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        return np.zeros(6), {}

    def step(self, action):
        return np.zeros(6), 0.0, False, True, {}


def test_verbose_prints_the_tiling_and_its_source(capsys):
    SarsaLambda("TileQ", "MountainCar-v0", verbose=1)
    out = capsys.readouterr().out
    assert (
        "Tile coding: 16 tilings, tile widths [0.18, 0.014] from sb3-er's tiling for MountainCar-v0 "
        "(Sutton & Barto (2018) section 10.1's tiling"
    ) in out
    SarsaLambda("TileQ", UnitBoxEnv(), policy_kwargs={"n_tilings": 4}, verbose=1)
    out = capsys.readouterr().out
    assert (
        "Tile coding: 4 tilings from policy_kwargs; tile widths [0.2, 0.2, 0.2, 0.2, 0.2, 0.2] from the generic "
        "rule: 5 tiles per bounded dimension" in out
    )
    SarsaLambda("TileQ", "MountainCar-v0", verbose=0)
    assert "Tile coding" not in capsys.readouterr().out


def test_a_saved_model_keeps_its_tiling(tmp_path):
    SarsaLambda("TileQ", "Acrobot-v1").save(tmp_path / "model")
    loaded = SarsaLambda.load(tmp_path / "model")
    assert widths_of(loaded) == pytest.approx(package_tilings()["Acrobot-v1"]["tile_widths"])
    assert loaded.policy.tile_coder.n_tilings == package_tilings()["Acrobot-v1"]["n_tilings"]


# --- rl-zoo entries ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("algo", zoo.ALGORITHM_NAMES)
@pytest.mark.parametrize("env_id", CLASSIC_IDS)
def test_zoo_entries_are_the_class_defaults_on_the_package_tilings(algo, env_id):
    kwargs = zoo.model_kwargs(algo, env_id)
    assert (kwargs["learning_rate"], kwargs["gamma"], kwargs["exploration_rate"]) == (0.2, 0.99, 0.05)
    assert "policy_kwargs" not in kwargs  # the tiling comes from sb3_er/data/tilings.yml
    assert zoo.load_hyperparameters(algo, env_id)["n_timesteps"] == 100_000
    assert kwargs.get("residual_zeta") == (0.5 if algo.startswith("residual") else None)


@pytest.mark.parametrize("algo", zoo.FRAMEWORK_ALGORITHM_NAMES)
@pytest.mark.parametrize("env_id", CLASSIC_IDS)
def test_framework_zoo_entries_build_on_the_package_widths(algo, env_id):
    kwargs = zoo.model_kwargs(algo, env_id)
    assert (kwargs["gamma"], kwargs["exploration_rate"]) == (0.99, 0.05)
    assert zoo.load_hyperparameters(algo, env_id)["n_timesteps"] == 100_000
    model = zoo.algorithm_classes()[algo]("TileQ", env_id, **kwargs)
    assert widths_of(model) == pytest.approx(package_tilings()[env_id]["tile_widths"])
    # LSPI factorises a system in the touched features: its entries keep the widths but use 4 tilings
    expected_tilings = 4 if algo == "lspi" else package_tilings()[env_id]["n_tilings"]
    assert model.policy.tile_coder.n_tilings == expected_tilings


def test_sb3_er_train_er_sigma_on_acrobot(tmp_path):
    zoo.train(
        [
            "--algo",
            "er_sigma",
            "--env",
            "Acrobot-v1",
            "-n",
            "600",
            "-f",
            str(tmp_path),
            "--seed",
            "0",
            "--eval-freq",
            "-1",
            "--verbose",
            "0",
        ]
    )
    model = ERSigma.load(tmp_path / "er_sigma" / "Acrobot-v1_1" / "Acrobot-v1.zip")
    assert model.num_timesteps == 600 and model.replay_phases >= 1
    assert widths_of(model) == pytest.approx(package_tilings()["Acrobot-v1"]["tile_widths"])
