"""Dyna: direct RL plus planning on a learned model (Sutton 1991; thesis 3.4 and Alg. 3-5), on tile-coded Q."""

from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from stable_baselines3.common.type_aliases import GymEnv, Schedule

from sb3_er.common import kernels
from sb3_er.common.batch import BufferedTileQAlgorithm, stored_transitions
from sb3_er.common.checks import check_choice, check_integer, check_number
from sb3_er.common.docstrings import inherit_parameters
from sb3_er.common.policies import TileQPolicy
from sb3_er.common.tile_coding import TileCoder

TARGETS = {"sarsa": kernels.TARGET_SARSA, "q_learning": kernels.TARGET_Q_LEARNING}
PLANNING_ACTIONS = ("stored", "uniform")
RNG_STREAM_PLANNING = kernels.RNG_STREAM_PLANNING  # spawn key of the planning generator

if TYPE_CHECKING:
    from scipy.spatial import KDTree


class NearestNeighbourModel:
    """The model M: (s, a) -> (r, s', terminal) of Dyna as an average over the nearest stored transitions of action a.

    Distances are measured in tile widths (each observation dimension divided by its tile width), so "near" means what
    the tile coding means by it; periodic dimensions wrap (a toroidal k-d tree, ``scipy.spatial.KDTree(boxsize=...)``).
    For a query (s, a), the ``n_neighbors`` stored transitions of action a nearest to s within ``radius`` tile widths
    predict (an expectation model, the uniform mean over them):

        r^ = mean r_j,   s'^ = s + mean (s'_j - s_j),   P(not terminal) = 1 - mean terminal_j.

    Averaging displacements s'_j - s_j rather than next states keeps the prediction at the queried s (a locally
    constant model of the dynamics). A query with no stored transition of action a within the radius is not covered:
    ``predict`` flags it and Dyna skips it. One k-d tree per action; fitting costs O(n log n), a batch of B queries
    O(B (log n + k)).

    :param coder: the tile coder that defines widths and wrap periods.
    :param n_neighbors: k, transitions averaged per prediction.
    :param radius: largest distance of a neighbour, in tile widths (Euclidean over the scaled dimensions).
    """

    def __init__(self, coder: TileCoder, n_neighbors: int, radius: float):
        self.inv_widths = coder.inv_widths.copy()
        self.box = coder.wrap_tiles.astype(np.float64)  # period in tile widths; 0 = not periodic
        self.periods = self.box / self.inv_widths  # in observation units where periodic
        self.n_actions = coder.n_actions
        self.n_neighbors = n_neighbors
        self.radius = radius
        self.trees: list[KDTree | None] = [None] * self.n_actions
        self.rewards: list[np.ndarray] = []
        self.displacements: list[np.ndarray] = []
        self.terminal: list[np.ndarray] = []
        self.n_transitions = 0

    def _scaled(self, observations: np.ndarray) -> np.ndarray:
        """Observations in tile widths, periodic dimensions wrapped into [0, period) as the k-d tree requires."""
        z = np.asarray(observations, dtype=np.float64) * self.inv_widths
        periodic = self.box > 0
        if periodic.any():
            wrapped = np.mod(z[:, periodic], self.box[periodic])
            z[:, periodic] = np.where(wrapped >= self.box[periodic], 0.0, wrapped)
        return z

    def _difference(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """a - b in observation units, periodic dimensions taken the short way round."""
        delta = np.asarray(a, dtype=np.float64) - b
        periodic = self.box > 0
        if periodic.any():
            period = self.periods[periodic]
            delta[:, periodic] = np.mod(delta[:, periodic] + 0.5 * period, period) - 0.5 * period
        return delta

    def fit(self, observations, actions, rewards, next_observations, terminal) -> "NearestNeighbourModel":
        """Index the transitions (n rows) by action.

        :param observations: states s, (n, D).
        :param actions: flat action indices, (n,).
        :param rewards: rewards, (n,).
        :param next_observations: next states s', (n, D).
        :param terminal: whether each s' is terminal, (n,) bool.
        """
        from scipy.spatial import KDTree  # imported when a model is first fit: Dyna alone needs it

        z = self._scaled(observations)
        displacement = self._difference(next_observations, observations)
        self.rewards, self.displacements, self.terminal = [], [], []
        for a in range(self.n_actions):
            rows = np.flatnonzero(actions == a)
            boxsize = self.box if np.any(self.box > 0) else None
            self.trees[a] = KDTree(z[rows], boxsize=boxsize) if rows.size else None
            self.rewards.append(rewards[rows])
            self.displacements.append(displacement[rows])
            self.terminal.append(terminal[rows].astype(np.float64))
        self.n_transitions = int(len(actions))
        return self

    def predict(self, observations: np.ndarray, actions: np.ndarray):
        """Predicted (s' (B, D), r (B,), P(not terminal) (B,), covered (B,) bool) for B queries (s, a).

        :param observations: query states s, (B, D).
        :param actions: query flat actions a, (B,).
        """
        observations = np.asarray(observations, dtype=np.float64)
        batch = observations.shape[0]
        next_observations = observations.copy()
        rewards = np.zeros(batch)
        continuation = np.zeros(batch)
        covered = np.zeros(batch, dtype=np.bool_)
        z = self._scaled(observations)
        for a in np.unique(actions):
            tree = self.trees[a]
            if tree is None:
                continue
            rows = np.flatnonzero(actions == a)
            k = min(self.n_neighbors, tree.n)
            distance, index = tree.query(z[rows], k=k, distance_upper_bound=self.radius)
            distance, index = distance.reshape(len(rows), k), index.reshape(len(rows), k)
            found = np.isfinite(distance)
            count = found.sum(axis=1)
            hit = count > 0
            index = np.where(found, index, 0)
            weight = found / np.maximum(count, 1)[:, None]
            rewards[rows] = (self.rewards[a][index] * weight).sum(axis=1)
            continuation[rows] = 1.0 - (self.terminal[a][index] * weight).sum(axis=1)
            next_observations[rows] += (self.displacements[a][index] * weight[:, :, None]).sum(axis=1)
            covered[rows] = hit
        return next_observations, rewards, continuation, covered

    def errors(self, observations, actions, rewards, next_observations):
        """One-step prediction errors on transitions: (next-state error in tile widths, |reward error|, covered).

        :param observations: states s, (n, D).
        :param actions: flat action indices, (n,).
        :param rewards: observed rewards, (n,).
        :param next_observations: observed next states s', (n, D).
        """
        predicted, predicted_rewards, _, covered = self.predict(observations, actions)
        state_error = np.linalg.norm(self._difference(predicted, next_observations) * self.inv_widths, axis=1)
        return state_error[covered], np.abs(predicted_rewards - rewards)[covered], covered


@inherit_parameters
class Dyna(BufferedTileQAlgorithm):
    """Dyna (Sutton 1991; thesis 3.4, Alg. 3-5 with the model database update of Alg. 4): after every real step, a
    direct one-step update of Q on the real transition, then ``planning_steps`` one-step updates on transitions that a
    learned model M predicts. With ``target="q_learning"`` this is Dyna-Q; ``"sarsa"`` draws a' epsilon-greedily at s'.

    The model is a ``NearestNeighbourModel`` over the stored transitions (k nearest stored transitions of the same
    action, in tile widths). Why this model: it needs no training and no hyperparameters beyond k and a radius, it is
    exact where the data is (a deterministic transition stored at s is predicted exactly at s), it generalises to
    queries between stored states by averaging their displacements, and it answers "no data here" instead of
    extrapolating: a tile-coded linear model would predict untried (s, a) as its initial zeros. Planning queries
    follow Dyna-Q: a stored state s drawn uniformly with its stored action (``planning_actions="stored"``), or with an
    action drawn uniformly (``"uniform"``), which uses the model where no transition of that action was stored at s.
    The prediction is an expectation: the planning target is r^ + gamma P(not terminal) v(s'^).

    Cost: the model is refit every ``model_refit_every`` real steps (at first after 1, 2, 4, ... steps while the data
    is smaller than that). Each fit draws the planning queries of the coming steps at once, predicts them in one
    batch k-d tree query and hashes the predicted next states' tiles; each real step then runs one numba kernel call
    (the direct update and its planning updates). A query drawn before a refit uses that older model, as Dyna's
    planning uses whatever model exists at the time.

    TensorBoard: ``train/model_error`` is the model's one-step prediction error on the transitions stored since its
    previous fit (held out from it): the mean distance between predicted and observed next state in tile widths;
    ``train/model_reward_error`` the mean |r^ - r|; ``train/model_coverage`` the share of planning queries the model
    answered; ``train/planning_updates`` the planning updates made.

    :param planning_steps: n, planning updates per real step (thesis: usually about 10); 0 is plain Q-learning/Sarsa.
    :param target: "q_learning" (Dyna-Q, T*) or "sarsa" (T^pi), for the direct and the planning updates.
    :param planning_actions: "stored" (Dyna-Q) or "uniform" (see above).
    :param n_neighbors: k of the nearest-neighbour model.
    :param model_radius: largest neighbour distance in tile widths.
    :param model_refit_every: real steps between model fits.
    :param buffer_size: transitions kept (the model's data).
    :param learning_rate: alpha, the step on Q of the direct and the planning updates alike (each of the N active
        weights moves by alpha * delta / N); a float or a schedule of the remaining progress.
    """

    def __init__(
        self,
        policy: str | type[TileQPolicy] = "TileQ",
        env: GymEnv | str | None = None,
        planning_steps: int = 10,
        target: Literal["q_learning", "sarsa"] = "q_learning",
        planning_actions: Literal["stored", "uniform"] = "stored",
        n_neighbors: int = 5,
        model_radius: float = 1.0,
        model_refit_every: int = 500,
        buffer_size: int = 1_000_000,
        replay_buffer_kwargs: dict[str, Any] | None = None,
        learning_rate: float | Schedule = 0.2,
        gamma: float = 0.99,
        exploration_rate: float = 0.05,
        trace_lambda: float | None = None,
        trace_cutoff: float = 0.01,
        value_watch: bool = True,
        value_bound_action: str = "warn",
        policy_kwargs: dict[str, Any] | None = None,
        stats_window_size: int = 100,
        tensorboard_log: str | None = None,
        verbose: int = 0,
        seed: int | None = None,
        device: str = "cpu",
        _init_setup_model: bool = True,
    ):
        self.planning_steps = planning_steps
        self.target = target
        self.planning_actions = planning_actions
        self.n_neighbors = n_neighbors
        self.model_radius = model_radius
        self.model_refit_every = model_refit_every
        self.planning_updates = 0
        self.model_fits = 0
        super().__init__(
            policy,
            env,
            buffer_size=buffer_size,
            replay_buffer_kwargs=replay_buffer_kwargs,
            learning_rate=learning_rate,
            gamma=gamma,
            exploration_rate=exploration_rate,
            trace_lambda=trace_lambda,
            trace_cutoff=trace_cutoff,
            value_watch=value_watch,
            value_bound_action=value_bound_action,
            policy_kwargs=policy_kwargs,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            verbose=verbose,
            seed=seed,
            device=device,
            _init_setup_model=_init_setup_model,
        )

    def _check_hyperparameters(self) -> None:
        super()._check_hyperparameters()
        check_integer("planning_steps", self.planning_steps, minimum=0)
        check_choice("target", self.target, TARGETS)
        check_choice("planning_actions", self.planning_actions, PLANNING_ACTIONS)
        check_integer("n_neighbors", self.n_neighbors, minimum=1)
        check_number("model_radius", self.model_radius, 0.0, low_open=True, unit=" (in tile widths)")
        check_integer("model_refit_every", self.model_refit_every, minimum=1, unit=" step")

    def _setup_model(self) -> None:
        super()._setup_model()
        self.dynamics_model: NearestNeighbourModel | None = None
        self._clear_plan()
        self._added_since_fit = 0
        self._model_error_sums = np.zeros(3)  # next-state error, reward error, count
        self._coverage_sums = np.zeros(2)  # covered queries, queries

    def _clear_plan(self) -> None:
        n_tilings = self.policy.tile_coder.n_tilings
        self._plan_slots = np.zeros((0, n_tilings), dtype=np.int64)
        self._plan_next_slots = np.zeros((0, n_tilings), dtype=np.int64)
        self._plan_actions = np.zeros(0, dtype=np.int64)
        self._plan_rewards = np.zeros(0)
        self._plan_continuation = np.zeros(0)
        self._plan_position = 0

    def _excluded_save_params(self) -> list[str]:
        return super()._excluded_save_params() + [
            "dynamics_model",
            "_plan_slots",
            "_plan_next_slots",
            "_plan_actions",
            "_plan_rewards",
            "_plan_continuation",
            "_plan_position",
            "_added_since_fit",
            "_model_error_sums",
            "_coverage_sums",
        ]

    def _on_buffer_replaced(self) -> None:
        self.dynamics_model = None
        self._clear_plan()
        self._added_since_fit = 0

    def _seed_generators(self, seed: int | None) -> None:
        super()._seed_generators(seed)
        self.planning_rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(RNG_STREAM_PLANNING,)))

    def fit_model(self) -> NearestNeighbourModel | None:
        """Refit M on the stored transitions and draw the planning queries of the next steps (Alg. 4 lines 2-7)."""
        data = stored_transitions(self.replay_buffer, include_open=True)
        n = len(data)
        if n == 0:
            return None
        self._observe_stored_rewards()
        coder = self.policy.tile_coder
        if self.dynamics_model is not None and self._added_since_fit > 0:
            held_out = slice(max(n - self._added_since_fit, 0), n)
            state_error, reward_error, _ = self.dynamics_model.errors(
                data.observations[held_out],
                data.actions[held_out],
                data.rewards[held_out],
                data.next_observations[held_out],
            )
            self._model_error_sums += (state_error.sum(), reward_error.sum(), state_error.size)
        self.dynamics_model = NearestNeighbourModel(coder, self.n_neighbors, self.model_radius).fit(
            data.observations, data.actions, data.rewards, data.next_observations, data.terminal
        )
        self.model_fits += 1
        self._added_since_fit = 0

        interval = min(self.model_refit_every, n)
        queries = self.planning_steps * interval
        rows = self.planning_rng.integers(0, n, size=queries)
        if self.planning_actions == "stored":
            actions = data.actions[rows]
        else:
            actions = self.planning_rng.integers(0, coder.n_actions, size=queries)
        predicted = self.dynamics_model.predict(data.observations[rows], actions)
        next_observations, rewards, continuation, covered = predicted
        next_slots = np.zeros((queries, coder.n_tilings), dtype=np.int64)
        kernels.batch_state_slots(next_observations, coder.layout, next_slots)
        self._plan_slots = np.ascontiguousarray(data.slots[rows])
        self._plan_next_slots = next_slots
        self._plan_actions = np.ascontiguousarray(actions, dtype=np.int64)
        self._plan_rewards = rewards
        self._plan_continuation = np.where(covered, continuation, -1.0)
        self._plan_position = 0
        self._coverage_sums += (covered.sum(), queries)
        return self.dynamics_model

    def _after_transition(self, env, slots, obs, action, reward, next_obs, terminated, done, info) -> None:
        self._store_transition(env, slots, obs, action, reward, next_obs, terminated, done, info)
        self._added_since_fit += 1
        if self.planning_steps > 0 and self._plan_position + self.planning_steps > self._plan_actions.shape[0]:
            self.fit_model()
        start = self._plan_position
        count = min(self.planning_steps, self._plan_actions.shape[0] - start)
        # once per environment step: plain tuples (kernels.bundles)
        transition = (slots, action, reward, terminated, next_obs, self._env_next_slots[env])
        plan = (
            self._plan_slots,
            self._plan_actions,
            self._plan_rewards,
            self._plan_continuation,
            self._plan_next_slots,
            start,
            count,
        )
        delta, updates, sum_abs_delta, status = kernels.dyna_step(
            tuple(self._weights()),
            self._plain_layout,
            tuple(self._update_rule(target_kind=TARGETS[self.target])),
            transition,
            plan,
            self.action_rng,
            tuple(self._scratch),
            self._watch_array,
        )
        self._plan_position = start + count
        self.planning_updates += updates
        where = "the direct update" if updates == 0 else f"planning update {updates}"
        self._check_status(
            status, where if status == kernels.STATUS_DIVERGED else "the direct or a planning update", delta, next_obs
        )
        self._td_error_sum += abs(delta) + sum_abs_delta
        self._td_error_count += 1 + updates

    def _record_train_metrics(self) -> None:
        super()._record_train_metrics()
        self.logger.record("train/planning_updates", self.planning_updates)
        self.logger.record("train/model_fits", self.model_fits)
        state_error, reward_error, count = self._model_error_sums
        if count:
            self.logger.record("train/model_error", state_error / count)
            self.logger.record("train/model_reward_error", reward_error / count)
            self._model_error_sums[:] = 0.0
        covered, queries = self._coverage_sums
        if queries:
            self.logger.record("train/model_coverage", covered / queries)
            self._coverage_sums[:] = 0.0
