"""The grid-world study of thesis chapter 5: value functions of the ER variants on the same data and the same replays.

A vanilla-ER learning run on the windy cliff grid world is stopped just after it first collects a positive goal payout
(Figure 5.2).
Its trajectory buffer is then given to fresh vanilla-ER, ER-sigma, residual-ER and residual-ER-sigma models, whose
replay generators get the same seed, and each replays the same trajectories: one phase of 10 x the stored trajectories
(the situation of Table 5.1 and Figure 5.7) and, separately, many phases without new samples (Table 5.2, the local
maxima of Figure 5.4). A Sarsa(lambda) run stopped at its first goal gives Figure 5.3. This is done with one tiling of
width 1 (tabular) and with 16 tilings of width 2 (the thesis's function approximation).

The maps show V(s) = max_a Q(s, a) for every cell outside the goal column; the statistics quantify the thesis's
findings: positive values in the doomed-to-fall (windy) area and the height of maxima.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
from stable_baselines3.common.callbacks import BaseCallback

ENV_ID = "sb3_er/WindyCliff-v0"
CASES = {"tabular": {"n_tilings": 1, "tile_widths": [1.0, 1.0]}, "tile coding": {"n_tilings": 16}}
REPLAY_VARIANTS = ("er", "er_sigma", "residual_er", "residual_er_sigma")
REPLAYS_PER_TRAJECTORY = 10
PESSIMISTIC = "er_pessimistic"
"""Name of vanilla ER with a pessimistic initial value (thesis Figure 5.5) among the replay variants."""
PESSIMISTIC_VALUE = -50.0
"""The pessimistic initial Q of Figure 5.5 (the thesis gives none): the cliff's reward, which is also the exact
discounted return of every path that ends in the cliff (k steps of -1, then -50: -(1 - gamma^k) / (1 - gamma) -
50 gamma^k = -50 for gamma = 0.98) and the infimum of every return, so no true value lies below it."""


class StopAtFirstGoal(BaseCallback):
    """Stops learning one step after the first episode that reaches the goal with a positive payout (or `max_episodes`).

    A goal entered at the southern cell pays 0 and teaches nothing about the goal's reward, so it does not count.
    Stopping one step later lets the algorithm close and store the goal trajectory (and finish its end-of-episode
    replay) before learning ends.

    :param max_episodes: learning stops after this many episodes even without a paying goal.
    """

    def __init__(self, max_episodes: int) -> None:
        super().__init__()
        self.max_episodes = max_episodes
        self.episodes = 0
        self.goal_reached = False
        self._stop_next_step = False

    def _on_step(self) -> bool:
        if self._stop_next_step:
            return False
        for index in np.flatnonzero(self.locals["dones"]):
            self.episodes += 1
            paid = bool(self.locals["infos"][index].get("goal_reached", False)) and self.locals["rewards"][index] > 0
            self.goal_reached |= paid
        self._stop_next_step = self.goal_reached or self.episodes >= self.max_episodes
        return True


def value_map(model, env) -> np.ndarray:
    """V(x, y) = max_a Q((x, y), a) of every non-goal cell, indexed [y, x] (y northwards).

    :param model: the trained model.
    :param env: its grid-world env.
    """
    unwrapped = env.unwrapped
    xs, ys = np.meshgrid(np.arange(unwrapped.goal_column), np.arange(unwrapped.height))
    cells = np.column_stack([xs.ravel(), ys.ravel()]).astype(np.float64)
    return model.policy.q_values(cells).max(axis=1).reshape(ys.shape)


def map_statistics(values: np.ndarray, first_windy_row: int) -> dict[str, float]:
    """Figures behind the thesis's reading of a value map: the windy (doomed-to-fall) area against the calm one.

    :param values: a value map V[y, x] of the non-goal cells (y northwards).
    :param first_windy_row: the first row in the wind.
    """
    windy, calm = values[first_windy_row:], values[:first_windy_row]
    return {
        "windy_max": float(windy.max()),
        "windy_mean": float(windy.mean()),
        "windy_positive_fraction": float((windy > 0).mean()),
        "calm_max": float(calm.max()),
        "calm_min": float(calm.min()),
    }


def _new_model(algo: str, env, policy_kwargs: dict, seed: int):
    """A model of `algo` with the grid world's thesis settings whose value watch counts the values outside the possible
    returns without warning: the studies report the count (``values_out_of_range``) beside each value map."""
    from sb3_er.zoo import algorithm_classes, model_kwargs

    kwargs = model_kwargs(algo, ENV_ID)
    kwargs["policy_kwargs"] = {**kwargs.get("policy_kwargs", {}), **policy_kwargs}
    return algorithm_classes()[algo]("TileQ", env, seed=seed, value_bound_action="ignore", **kwargs)


def learn_until_goal(algo: str, env, policy_kwargs: dict, seed: int, max_episodes: int = 1000):
    """A learning run of `algo` stopped after the episode in which it first reaches the goal.

    :param algo: the algorithm's rl-zoo name.
    :param env: the grid-world env.
    :param policy_kwargs: the policy's tiling settings (the case's).
    :param seed: the seed.
    :param max_episodes: the most episodes to learn (default 1000).
    """
    model = _new_model(algo, env, policy_kwargs, seed)
    stopper = StopAtFirstGoal(max_episodes)
    model.learn(total_timesteps=max_episodes * env.unwrapped.max_episode_steps + 1, callback=stopper)
    if not stopper.goal_reached:
        raise RuntimeError(f"{algo} did not reach the goal within {max_episodes} episodes (seed {seed})")
    return model, stopper.episodes


def positive_cells(values: np.ndarray, first_windy_row: int) -> dict[str, int]:
    """How far the goal's reward has spread in a value map V[y, x] (non-goal cells): the number of cells with V > 0
    in all (``positive_cells``), below the wind (``calm_positive_cells``) and in it (``windy_positive_cells``).

    :param values: a value map V[y, x] of the non-goal cells (y northwards).
    :param first_windy_row: the first row in the wind.
    """
    return {
        "positive_cells": int((values > 0).sum()),
        "calm_positive_cells": int((values[:first_windy_row] > 0).sum()),
        "windy_positive_cells": int((values[first_windy_row:] > 0).sum()),
    }


def replay_variants(pessimistic_value: float | None = None) -> dict[str, tuple[str, dict]]:
    """The replay variants of the value-map study: name -> (algorithm, policy kwargs on top of the case's tiling).
    With `pessimistic_value`, also vanilla ER whose Q starts at that value everywhere (:data:`PESSIMISTIC`).

    :param pessimistic_value: the pessimistic initial Q (default None: no pessimistic variant).
    """
    variants = {algo: (algo, {}) for algo in REPLAY_VARIANTS}
    if pessimistic_value is not None:
        variants[PESSIMISTIC] = ("er", {"initial_value": float(pessimistic_value)})
    return variants


def replay_model(algo: str, env, policy_kwargs: dict, seed: int, buffer_path: Path):
    """A fresh `algo` model (the grid world's thesis settings, `policy_kwargs`, `seed`) holding the replay buffer
    saved at `buffer_path`, its trajectory generator seeded with `seed`: every such model replays the same
    trajectories (thesis 5.2-5.4, "the exact same samples are replayed").

    :param algo: the algorithm's rl-zoo name.
    :param env: the grid-world env.
    :param policy_kwargs: the policy's tiling settings (the case's).
    :param seed: the seed.
    :param buffer_path: the saved replay buffer.
    """
    model = _new_model(algo, env, policy_kwargs, seed)
    model.load_replay_buffer(buffer_path, truncate_last_traj=False)
    model.replay_buffer.truncate_open_trajectory()  # the step the collector took into its next episode ends there
    model.seed_replay(seed)
    return model


def same_data_value_maps(
    seed: int = 0, long_phases: int = 30, pessimistic_value: float | None = None
) -> tuple[dict[str, dict[str, dict[str, np.ndarray]]], pd.DataFrame]:
    """Value maps per (situation, case, algorithm) and their statistics, with the data and replays shared per case.

    Situations: ``"after goal"`` (one replay phase, Table 5.1) and ``"long replay"`` (`long_phases` phases, Table 5.2).
    With `pessimistic_value` (e.g. :data:`PESSIMISTIC_VALUE`), vanilla ER with Q starting at that value replays the
    same data too, under the name :data:`PESSIMISTIC` (thesis Figure 5.5).

    :param seed: the seed of the collecting runs and the replays (default 0).
    :param long_phases: replay phases of the long replay (default 30).
    :param pessimistic_value: the pessimistic initial Q (default None: no pessimistic variant).
    """
    import gymnasium as gym

    import sb3_er_envs  # noqa: F401

    variants = replay_variants(pessimistic_value)
    env = gym.make(ENV_ID)
    first_windy_row = env.unwrapped.first_windy_row
    maps: dict[str, dict[str, dict[str, np.ndarray]]] = {"after goal": {}, "long replay": {}}
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        for case, policy_kwargs in CASES.items():
            collector, episodes = learn_until_goal("er", env, policy_kwargs, seed)
            buffer_path = Path(scratch) / "buffer.pkl"
            collector.save_replay_buffer(buffer_path)
            n_trajectories = collector.replay_buffer.n_trajectories
            sarsa, sarsa_episodes = learn_until_goal("sarsa_lambda", env, policy_kwargs, seed)
            for situation, phases in (("after goal", 1), ("long replay", long_phases)):
                maps[situation][case] = {"sarsa_lambda": value_map(sarsa, env)}
                rows.append(
                    {
                        "situation": situation,
                        "case": case,
                        "algorithm": "sarsa_lambda",
                        "episodes": sarsa_episodes,
                        "replayed_trajectories": 0,
                        **map_statistics(maps[situation][case]["sarsa_lambda"], first_windy_row),
                        "values_out_of_range": sarsa.values_out_of_range,
                    }
                )
                for name, (algo, extra_policy_kwargs) in variants.items():
                    model = replay_model(algo, env, {**policy_kwargs, **extra_policy_kwargs}, seed, buffer_path)
                    for _ in range(phases):
                        model.replay(REPLAYS_PER_TRAJECTORY * n_trajectories)
                    maps[situation][case][name] = value_map(model, env)
                    rows.append(
                        {
                            "situation": situation,
                            "case": case,
                            "algorithm": name,
                            "episodes": episodes,
                            "replayed_trajectories": phases * REPLAYS_PER_TRAJECTORY * n_trajectories,
                            **map_statistics(maps[situation][case][name], first_windy_row),
                            "values_out_of_range": model.values_out_of_range,
                        }
                    )
    env.close()
    return maps, pd.DataFrame(rows)
