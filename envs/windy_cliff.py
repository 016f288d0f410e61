"""Windy cliff grid world of thesis section 5.1 (Figure 5.1), in our concrete reading (the
documentation's windy-cliff page gives the readings).

The grid has ``width`` x ``height`` cells (default 10 x 7); cell ``(x, y)`` has ``x`` growing eastwards and ``y``
northwards, so ``(0, 0)`` is the south-west corner, where every episode starts.

Dynamics, given the cell ``(x, y)`` the action is taken in:

* outside the wind (``y < height - wind_rows``) the 8 actions are king's moves (N, NE, E, SE, S, SW, W, NW); a move
  that would leave the grid through the west, south or east edge keeps that coordinate in place;
* in the wind (the top ``wind_rows`` rows, default 3) every action has the same effect: with probability
  ``wind_probability`` (default 1/2) the agent is blown one cell north, otherwise it stays where it is;
* leaving the grid through the north edge is the fall from the cliff: reward ``fall_reward`` (-50) and ``terminated``;
* the east column ``x = width - 1`` is the goal: entering it ends the episode (``terminated``) with the payout
  ``goal_reward * y / (height - 1)``, i.e. ``goal_reward`` (50) at the most northern cell down linearly to 0 at the most
  southern one. Inside the wind no action moves east, so the best payout that can actually be collected is the one of
  the lowest windy row, entered diagonally from the row below: success and failure lie side by side (thesis 5.1);
* every other step pays ``step_reward`` (-1). The terminal step pays the fall or goal reward instead of the step cost,
  so the figures of the thesis (-50, 50) are the rewards the agent sees;
* after ``max_episode_steps`` (100) steps the episode is ``truncated``.

Observations are the cell coordinates ``(x, y)`` as floats: tile width 1 with a single tiling is exactly tabular, and
the thesis's function approximation is 16 tilings of width 2 (``tile_widths``).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from sb3_er_envs import discrete_action_index

#: King's moves as (dx, dy), clockwise from north; the action index is the position in this tuple.
KING_MOVES = ((0, 1), (1, 1), (1, 0), (1, -1), (0, -1), (-1, -1), (-1, 0), (-1, 1))
ACTION_NAMES = ("N", "NE", "E", "SE", "S", "SW", "W", "NW")

_CELL_PIXELS = 16
_COLOURS = {
    "ground": (235, 235, 235),
    "wind": (190, 215, 245),
    "cliff": (120, 40, 40),
    "start": (200, 200, 120),
    "agent": (30, 30, 30),
    "grid": (160, 160, 160),
}


class Outcome(NamedTuple):
    """One possible result of taking an action: its probability, next cell, reward and how the episode ends."""

    probability: float
    next_cell: tuple[int, int]
    reward: float
    fell: bool
    goal_reached: bool


class WindyCliffEnv(gym.Env):
    """Windy cliff grid world (thesis 5.1): king's moves below the wind, a cliff north of the wind, a goal column east.

    Parameters
    ----------
    width, height:
        Grid size in cells (default 10 x 7).
    wind_rows:
        Number of windy rows at the top of the grid (default 3); the start row must stay out of the wind.
    wind_probability:
        Probability that an action in the wind blows the agent one cell north (default 0.5); otherwise it stays.
    step_reward, fall_reward, goal_reward:
        Reward of an ordinary step (-1), of falling from the cliff (-50), and of the most northern goal cell (50).
    max_episode_steps:
        Steps after which the episode is truncated (100).
    render_mode:
        ``None`` or ``"rgb_array"``.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(
        self,
        width: int = 10,
        height: int = 7,
        wind_rows: int = 3,
        wind_probability: float = 0.5,
        step_reward: float = -1.0,
        fall_reward: float = -50.0,
        goal_reward: float = 50.0,
        max_episode_steps: int = 100,
        render_mode: str | None = None,
    ) -> None:
        if int(width) != width or width < 2:
            raise ValueError(f"width must be an integer of at least 2 (one column plus the goal column), got {width}")
        if int(height) != height or height < 2:
            raise ValueError(f"height must be an integer of at least 2, got {height}")
        if int(wind_rows) != wind_rows or not 0 <= wind_rows < height:
            raise ValueError(
                f"wind_rows must be an integer in [0, height - 1] = [0, {height - 1}] so that the start row is calm, "
                f"got {wind_rows}"
            )
        if not 0.0 <= wind_probability <= 1.0:
            raise ValueError(f"wind_probability must lie in [0, 1], got {wind_probability}")
        if int(max_episode_steps) != max_episode_steps or max_episode_steps < 1:
            raise ValueError(f"max_episode_steps must be a positive integer, got {max_episode_steps}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")

        self.width = int(width)
        self.height = int(height)
        self.wind_rows = int(wind_rows)
        self.wind_probability = float(wind_probability)
        self.step_reward = float(step_reward)
        self.fall_reward = float(fall_reward)
        self.goal_reward = float(goal_reward)
        self.max_episode_steps = int(max_episode_steps)
        self.render_mode = render_mode

        self.start_cell = (0, 0)
        self.goal_column = self.width - 1
        self.first_windy_row = self.height - self.wind_rows
        self.dt = 1.0
        self.tile_widths = np.array([2.0, 2.0])
        self.wrap_periods = None

        self.observation_space = spaces.Box(
            low=np.zeros(2), high=np.array([self.width - 1, self.height - 1], dtype=np.float64), dtype=np.float64
        )
        self.action_space = spaces.Discrete(len(KING_MOVES))

        self._x, self._y = self.start_cell
        self._steps = 0

    def is_windy(self, y: int) -> bool:
        """Whether row ``y`` lies in the wind.

        :param y: the row, 0 the southernmost.
        """
        return y >= self.first_windy_row

    def goal_payout(self, y: int) -> float:
        """Reward for entering the goal column at row ``y``: linear from 0 (south) to ``goal_reward`` (north).

        :param y: the row, 0 the southernmost.
        """
        return self.goal_reward * y / (self.height - 1)

    def outcome(self, cell: tuple[int, int], action: int, blown: bool) -> tuple[tuple[int, int], float, bool, bool]:
        """Deterministic result of ``action`` in ``cell`` given whether the wind blows: (next cell, reward, fell, goal).

        ``blown`` only matters in the wind; ``next_cell`` after a fall is the cell the agent fell from.

        :param cell: the (x, y) cell acted in.
        :param action: the action index.
        :param blown: whether the wind blows in this step.
        """
        x, y = cell
        if self.is_windy(y):
            nx, ny = x, y + 1 if blown else y
        else:
            dx, dy = KING_MOVES[action]
            nx = min(max(x + dx, 0), self.width - 1)
            ny = max(y + dy, 0)
        if ny >= self.height:
            return (x, y), self.fall_reward, True, False
        if nx == self.goal_column:
            return (nx, ny), self.goal_payout(ny), False, True
        return (nx, ny), self.step_reward, False, False

    def transition_distribution(self, cell: tuple[int, int], action: int) -> list[Outcome]:
        """All outcomes of ``action`` in the non-terminal ``cell`` with their probabilities (merged, zero ones dropped).

        :param cell: the (x, y) cell, not terminal.
        :param action: the action index.
        """
        x, y = self._checked_cell(cell)
        action = discrete_action_index(action, len(KING_MOVES))
        if not self.is_windy(y):
            return [Outcome(1.0, *self.outcome(cell, action, blown=False))]
        merged: dict[tuple, float] = {}
        for blown, probability in ((False, 1.0 - self.wind_probability), (True, self.wind_probability)):
            if probability > 0.0:
                key = self.outcome((x, y), action, blown)
                merged[key] = merged.get(key, 0.0) + probability
        return [Outcome(probability, *key) for key, probability in merged.items()]

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start at the south-west corner, or at ``options["cell"]`` (any non-goal cell, e.g. for exploring starts).

        :param seed: the seed of the env's generator (default None).
        :param options: ``{"cell": (x, y)}`` to start elsewhere (default None).
        """
        super().reset(seed=seed)
        cell = self.start_cell if options is None else options.get("cell", self.start_cell)
        self._x, self._y = self._checked_cell(cell)
        self._steps = 0
        return self._observation(), {"fell": False, "goal_reached": False}

    @property
    def reward_bounds(self) -> dict:
        """Where the rewards lie (the value watch of sb3-er reads it): ``step_reward`` on every step that does not end
        the episode, the fall reward or a goal payout in [0, goal_reward] on a terminating one."""
        ends = (self.fall_reward, 0.0, self.goal_reward)
        return {"step": (self.step_reward, self.step_reward), "terminal": (min(ends), max(ends))}

    def step(self, action):
        action = discrete_action_index(action, len(KING_MOVES))
        blown = self.is_windy(self._y) and self.np_random.random() < self.wind_probability
        (self._x, self._y), reward, fell, goal_reached = self.outcome((self._x, self._y), action, blown)
        self._steps += 1
        terminated = fell or goal_reached
        truncated = not terminated and self._steps >= self.max_episode_steps
        return self._observation(), reward, terminated, truncated, {"fell": fell, "goal_reached": goal_reached}

    def render(self) -> np.ndarray | None:
        """An RGB image: calm cells grey, windy cells blue, the cliff as a dark red strip along the north edge, goal
        cells green (brighter for a higher payout), the start cell yellow and the agent as a dark square."""
        if self.render_mode is None:
            gym.logger.warn("render() called without render_mode; pass render_mode='rgb_array' to WindyCliffEnv")
            return None
        px = _CELL_PIXELS
        rows = self.height + 1
        image = np.empty((rows * px, self.width * px, 3), dtype=np.uint8)
        image[:px] = _COLOURS["cliff"]
        for y in range(self.height):
            top = (self.height - y) * px
            for x in range(self.width):
                if x == self.goal_column:
                    share = self.goal_payout(y) / self.goal_reward if self.goal_reward else 0.0
                    colour = (int(150 - 100 * share), int(190 + 60 * share), int(150 - 100 * share))
                elif (x, y) == self.start_cell:
                    colour = _COLOURS["start"]
                else:
                    colour = _COLOURS["wind"] if self.is_windy(y) else _COLOURS["ground"]
                image[top : top + px, x * px : (x + 1) * px] = colour
        image[px::px, :] = _COLOURS["grid"]
        image[:, ::px] = _COLOURS["grid"]
        agent_top = (self.height - self._y) * px
        margin = px // 4
        image[agent_top + margin : agent_top + px - margin, self._x * px + margin : (self._x + 1) * px - margin] = (
            _COLOURS["agent"]
        )
        return image

    def _observation(self) -> np.ndarray:
        return np.array((self._x, self._y), dtype=np.float64)

    def _checked_cell(self, cell) -> tuple[int, int]:
        x, y = (int(c) for c in cell) if len(cell) == 2 else (-1, -1)
        if (x, y) != tuple(cell) or not (0 <= x < self.goal_column and 0 <= y < self.height):
            raise ValueError(
                f"cell must be a non-goal cell (x, y) with integer 0 <= x < {self.goal_column} and "
                f"0 <= y < {self.height}, got {cell!r}"
            )
        return x, y
