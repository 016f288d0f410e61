"""Why replayed values leave the possible returns: thesis 5.3.1's self-affecting state (Figure 5.6) and ER-sigma on
the simplest walker and the pendulum (the page ``docs/value_growth.md``; figures by ``benchmarks/value_growth/run.py``).

Three tools, all on the public API (a TileQ model, its TrajectoryReplayBuffer, ``model.replay``):

1. **Figure 5.6's self-affecting sample** (:func:`self_affecting_model`, :func:`replay_values`): one hand-made
transition
   (s, a, r, s') whose s' shares ``shared`` of the N tiles of s, stored in a model's buffer and replayed alone, and its
   closed form (:func:`closed_form`). Per replay, with f = shared / N, step alpha on Q, discount gamma and the residual
   factor zeta (0 without): Q(s, a) moves by p alpha delta and the bootstrap value at s' by q alpha delta, so that
   delta_{n+1} = (1 - alpha kappa) delta_n with kappa = p - gamma q, and

       Q_n(s, a) = Q_0(s, a) + p delta_0 (1 - (1 - alpha kappa)^n) / kappa,

   vanilla ER          p = 1,               q = f
   ER-sigma            p = 1,               q = 1            (s' has only the shared tiles visited)
   residual ER         p = 1 - zeta gamma f, q = f - zeta gamma
   residual ER-sigma   p = 1 - zeta gamma f, q = 1 - zeta gamma.

   ER-sigma's q = 1 whatever f: sigma(s') is the mean weight of the visited (shared) tiles, given to every unvisited
   tile of s', so Q~(s', a) = N / shared * (shared weights) moves exactly as much as Q(s, a): any overlap makes the
   sample a full self-loop, whose value is r / (1 - gamma) plus the amplified initial gap. The residual term
   subtracts zeta gamma alpha delta / N from every tile of phi(s', a); under ER-sigma only its share on the visited
   (shared) tiles counts, the unvisited ones being replaced by sigma(s').
2. **The target side by side** (:func:`target_comparison`): for every stored transition, on the same weights and
   visits, Q(s_t, a_t), the vanilla target r + gamma max_a Q(s', a) and the ER-sigma target r + gamma max_a Q~(s', a)
   (Eq. 5.4; greedy a', no exploration draw), W(s', .) of the chosen action, sum_a W(s', a), whether no action at s'
   was visited (sigma's fallback), and the share of phi(s_t, a_t) that the chosen phi(s', a') shares.
3. **The replay operator's gain** (:func:`replay_gain`): the stored data replayed with every reward set to 0, from the
   learned weights; the true values are then 0 and the map theta -> theta' is positively homogeneous, so its growth
   factor per replay phase tells whether replay contracts (< 1) or expands (> 1) whatever the rewards.
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium as gym
import numba as nb
import numpy as np
from gymnasium import spaces

from sb3_er.common import kernels
from sb3_er.common.kernels.policy import argmax_first
from sb3_er.common.kernels.replay import er_sigma_td_error
from sb3_er.common.kernels.tiles import all_q_values, q_value, visited_q_values

#: Figure 5.6's two cases: (r, Q(s_k, a_k) initially, Q(s_{k+1}, a_k) initially).
CASES = {
    "a": {"reward": 10.0, "q_state": 0.0, "q_next": 0.0},
    "b": {"reward": -1.0, "q_state": -10.0, "q_next": -5.0},
}
#: The four ER algorithms of thesis chapter 5 by display name: (class name in sb3_er, sigma, residual).
VARIANTS = {
    "ER": ("ER", False, False),
    "ER-σ": ("ERSigma", True, False),
    "residual ER": ("ResidualER", False, True),
    "residual ER-σ": ("ResidualERSigma", True, True),
}
#: Figure 5.6's alpha and gamma.
FIGURE_ALPHA, FIGURE_GAMMA = 0.25, 0.98


class ArtificialSamplesEnv(gym.Env):
    """A stand-in env that only gives a model its spaces (thesis 5.3.1: "artificial samples"): a 1-D state in
    [-2, 2] tiled with width 1. It is never stepped: samples are written into the buffer.

    :param n_actions: the number of discrete actions (default 1).
    :param rewards: (low, high) of the rewards its samples will pay, declared as ``reward_bounds`` (no termination) so
        that the value watch knows the possible returns (default (0, 0)).
    """

    metadata = {"render_modes": []}
    tile_widths = (1.0,)

    def __init__(self, n_actions: int = 1, rewards: tuple[float, float] = (0.0, 0.0)):
        self.observation_space = spaces.Box(-2.0, 2.0, shape=(1,), dtype=np.float64)
        self.action_space = spaces.Discrete(n_actions)
        self.reward_bounds = {"step": (float(rewards[0]), float(rewards[1]))}

    def reset(self, *, seed=None, options=None):
        raise RuntimeError("ArtificialSamplesEnv only gives a model its spaces; store samples in the buffer instead")

    def step(self, action):
        raise RuntimeError("ArtificialSamplesEnv only gives a model its spaces; store samples in the buffer instead")


@dataclass
class SelfAffectingSample:
    """A model holding Figure 5.6's single stored transition, and the sample.

    :param model: the ER-family model whose replay buffer holds the one transition.
    :param state: s_k, shape (1,).
    :param next_state: s_{k+1}, shape (1,), sharing ``shared`` tiles with s_k.
    :param reward: r_{k+1}.
    :param shared: how many of the model's tilings s_k and s_{k+1} share.
    """

    model: object
    state: np.ndarray
    next_state: np.ndarray
    reward: float
    shared: int

    def q_state(self) -> float:
        """Q(s_k, a_k)."""
        return float(self.model.policy.q_values(self.state[None])[0, 0])

    def q_next(self) -> float:
        """Q(s_{k+1}, a_k) itself (without sigma)."""
        return float(self.model.policy.q_values(self.next_state[None])[0, 0])


def self_affecting_model(
    variant: str,
    case: str = "a",
    n_tilings: int = 4,
    shared: int = 3,
    learning_rate: float = FIGURE_ALPHA,
    gamma: float = FIGURE_GAMMA,
    residual_zeta: float = 1.0,
    memory_size: int = 2**16,
    value_bound_action: str = "ignore",
    **model_kwargs,
) -> SelfAffectingSample:
    """Figure 5.6's example: a model of `variant` (a key of :data:`VARIANTS`) whose buffer holds one transition
    (s_k, a_k, r, s_{k+1}), s_{k+1} sharing `shared` of the `n_tilings` tiles of s_k, with the case's reward and
    initial values (a key of :data:`CASES`).

    One action, so that a_k is the greedy action at s_{k+1} (the premise of thesis 5.3.1). Every weight starts at
    Q(s_{k+1}, a_k)_init / N, so Q is that value everywhere; the weights of the tiles of s_k that s_{k+1} does not share
    are then moved so that Q(s_k, a_k) is the case's initial value (case b: -10 at s_k against -5 at s_{k+1}). The
    transition is stored as a truncated trajectory: replay bootstraps from s_{k+1}, and no sample corrects
    Q(s_{k+1}, a_k). Exploration is off (epsilon 0), so every replay is deterministic.

    :param variant: the algorithm, a key of :data:`VARIANTS`.
    :param case: the reward and initial values, a key of :data:`CASES` (default "a").
    :param n_tilings: the number of tilings N (default 4).
    :param shared: tiles s_{k+1} shares with s_k (default 3).
    :param learning_rate: the step size alpha (default 0.25).
    :param gamma: the discount factor (default 0.98).
    :param residual_zeta: zeta of the residual variants (default 1).
    :param memory_size: the hashed weight table's size (default 2^16).
    :param value_bound_action: the value watch's action (default "ignore": values grow here on purpose).
    :param model_kwargs: further keyword arguments of the model, e.g. the stabilizers (``truncate_targets=True``).
    """
    import sb3_er

    if variant not in VARIANTS:
        raise ValueError(f"unknown variant {variant!r}; choose one of {', '.join(VARIANTS)}")
    if case not in CASES:
        raise ValueError(f"unknown case {case!r}; choose one of {', '.join(CASES)}")
    if not (isinstance(n_tilings, int) and n_tilings >= 1 and isinstance(shared, int) and 1 <= shared <= n_tilings):
        raise ValueError(f"need 1 <= shared <= n_tilings, got shared={shared!r}, n_tilings={n_tilings!r}")
    values = CASES[case]
    if shared == n_tilings and values["q_state"] != values["q_next"]:
        raise ValueError("with every tile shared s_{k+1} has the value of s_k: the case needs shared < n_tilings")
    class_name, _, residual = VARIANTS[variant]
    kwargs = {"residual_zeta": residual_zeta} if residual else {}
    env = ArtificialSamplesEnv(rewards=(values["reward"], values["reward"]))
    model = getattr(sb3_er, class_name)(
        "TileQ",
        env,
        learning_rate=learning_rate,
        gamma=gamma,
        exploration_rate=0.0,
        seed=0,
        value_bound_action=value_bound_action,
        policy_kwargs={"n_tilings": n_tilings, "initial_value": values["q_next"], "memory_size": memory_size},
        **kwargs,
        **model_kwargs,
    )
    coder = model.policy.tile_coder
    # Tiling k covers [j - k/N, j + 1 - k/N): s = c + 0.5/N and s' = s + (N - shared)/N cross the boundaries of
    # exactly N - shared tilings, for any integer c; the first c whose 2N - shared tiles hash to distinct slots.
    for shift in range(-2, 2):
        state = np.array([shift + 0.5 / n_tilings])
        next_state = state + (n_tilings - shared) / n_tilings
        features, next_features = coder.feature_indices(state, 0), coder.feature_indices(next_state, 0)
        if np.unique(np.r_[features, next_features]).size == 2 * n_tilings - shared:
            break
    else:
        raise RuntimeError("the hashed tiles of the example collide; choose another memory size")
    theta = model.policy.theta_array
    own = np.setdiff1d(features, next_features)
    if own.size:
        theta[own] += (values["q_state"] - theta[features].sum()) / own.size
    buffer = model.replay_buffer
    buffer.add(state, coder.slots(state), 0, values["reward"], next_state)
    buffer.close_trajectory(next_state, terminated=False)
    return SelfAffectingSample(model, state, next_state, values["reward"], shared)


def replay_values(sample: SelfAffectingSample, n_replays: int) -> np.ndarray:
    """Q(s_k, a_k) before and after each of `n_replays` replays of the stored sample (n_replays + 1 values), each a
    replay phase of one trajectory through ``model.replay`` (the kernels' own update).

    :param sample: the model of :func:`self_affecting_model`.
    :param n_replays: the number of replays.
    """
    values = [sample.q_state()]
    for _ in range(n_replays):
        sample.model.replay(1)
        values.append(sample.q_state())
    return np.array(values)


def closed_form(
    variant: str,
    case: str,
    n_replays: int,
    n_tilings: int = 4,
    shared: int = 3,
    learning_rate: float = FIGURE_ALPHA,
    gamma: float = FIGURE_GAMMA,
    residual_zeta: float = 1.0,
) -> np.ndarray:
    """Q_n(s_k, a_k) for n = 0..n_replays by the closed form of the module docstring (the hand computation).

    :param variant: the algorithm, a key of :data:`VARIANTS`.
    :param case: the reward and initial values, a key of :data:`CASES`.
    :param n_replays: the number of replays.
    :param n_tilings: the number of tilings N (default 4).
    :param shared: tiles s_{k+1} shares with s_k (default 3).
    :param learning_rate: the step size alpha (default 0.25).
    :param gamma: the discount factor (default 0.98).
    :param residual_zeta: zeta of the residual variants (default 1).
    """
    _, sigma, residual = VARIANTS[variant]
    f = shared / n_tilings
    zeta = residual_zeta if residual else 0.0
    p = 1.0 - zeta * gamma * f
    q = (1.0 - zeta * gamma) if sigma else (f - zeta * gamma)
    kappa = p - gamma * q
    values = CASES[case]
    delta0 = values["reward"] + gamma * values["q_next"] - values["q_state"]
    n = np.arange(n_replays + 1)
    return values["q_state"] + p * delta0 * (1.0 - (1.0 - learning_rate * kappa) ** n) / kappa


def limit_value(
    variant: str,
    case: str,
    n_tilings: int = 4,
    shared: int = 3,
    gamma: float = FIGURE_GAMMA,
    residual_zeta: float = 1.0,
) -> float:
    """lim Q_n(s_k, a_k) (where 0 < alpha kappa < 2): Q_0 + p delta_0 / kappa.

    :param variant: the algorithm, a key of :data:`VARIANTS`.
    :param case: the reward and initial values, a key of :data:`CASES`.
    :param n_tilings: the number of tilings N (default 4).
    :param shared: tiles s_{k+1} shares with s_k (default 3).
    :param gamma: the discount factor (default 0.98).
    :param residual_zeta: zeta of the residual variants (default 1).
    """
    _, sigma, residual = VARIANTS[variant]
    f = shared / n_tilings
    zeta = residual_zeta if residual else 0.0
    p = 1.0 - zeta * gamma * f
    q = (1.0 - zeta * gamma) if sigma else (f - zeta * gamma)
    values = CASES[case]
    delta0 = values["reward"] + gamma * values["q_next"] - values["q_state"]
    return values["q_state"] + p * delta0 / (p - gamma * q)


# --- The target side by side on stored data ---------------------------------------------------------------------

COMPARISON_COLUMNS = (
    "q_sa",
    "target_vanilla",
    "target_sigma",
    "w_chosen",
    "w_total",
    "no_action_visited",
    "overlap_vanilla",
    "overlap_sigma",
    "terminal",
)


@nb.njit(cache=True)
def _compare_targets(weights, data, next_slots, terminal, layout, rule, scratch, out):
    """Per stored row i of ``data``: Q(s, a), vanilla ER's greedy target, ER-sigma's greedy target (the kernels' own
    :func:`~sb3_er.common.kernels.replay.er_sigma_td_error` under ``rule``: Q-learning, epsilon 0), W of the action it
    chose and of all actions at s', whether no action was visited there, and the shares of phi(s, a) that the
    chosen next feature vectors share (columns :data:`COMPARISON_COLUMNS`)."""
    theta = weights.theta
    n, n_tilings = data.slots.shape
    q, w = scratch.q, scratch.w
    has_initial = weights.initial_low != 0.0 or weights.initial_span != 0.0
    rng = np.zeros(4, dtype=np.uint64)  # never drawn from: greedy targets (epsilon 0, Q-learning)
    no_watch = np.zeros(0)
    for i in range(n):
        a = data.actions[i]
        out[i, 0] = q_value(theta, data.slots[i], layout, a)
        out[i, 8] = terminal[i]
        if terminal[i]:
            out[i, 1] = data.rewards[i]
            out[i, 2] = data.rewards[i]
            continue
        all_q_values(theta, next_slots[i], layout, q)
        greedy = argmax_first(q)
        out[i, 1] = data.rewards[i] + rule.gamma * q[greedy]
        _, target, _, chosen = er_sigma_td_error(
            weights, data, i, next_slots[i], False, layout, rule, rng, scratch, no_watch
        )
        out[i, 2] = target
        visited_q_values(theta, data.visits, next_slots[i], layout, has_initial, q, w)
        total = 0.0
        for b in range(w.shape[0]):
            total += w[b]
        out[i, 3] = w[chosen]
        out[i, 4] = total
        out[i, 5] = total == 0.0
        for column, b in ((6, greedy), (7, chosen)):
            shared = 0
            for k in range(n_tilings):
                feature = data.slots[i, k] * layout.stride + layout.action_columns[k, a]
                for j in range(n_tilings):
                    if next_slots[i, j] * layout.stride + layout.action_columns[j, b] == feature:
                        shared += 1
                        break
            out[i, column] = shared / n_tilings


def stored_transitions(buffer) -> tuple[np.ndarray, ...]:
    """(rows, tiles of s_{t+1}, terminal) of every stored transition, oldest first, the open trajectory included.

    :param buffer: the TrajectoryReplayBuffer.
    """
    capacity = buffer.capacity
    rows, next_slots, terminal = [], [], []
    for i in range(buffer.n_trajectories):
        j = (buffer.oldest_trajectory + i) % capacity
        start, length = int(buffer.trajectory_start[j]), int(buffer.trajectory_length[j])
        r = (start + np.arange(length)) % capacity
        rows.append(r)
        next_slots.append(np.vstack([buffer.slots[r[1:]], buffer.trajectory_next_slots[j][None]]))
        terminal.append(np.r_[np.zeros(length - 1, bool), bool(buffer.trajectory_terminated[j])])
    if buffer.open_length:
        start = (buffer.write_row) % capacity
        r = (start + np.arange(buffer.open_length)) % capacity
        rows.append(r)
        next_slots.append(np.vstack([buffer.slots[r[1:]], buffer.tile_coder.slots(buffer.open_next_obs)[None]]))
        terminal.append(np.zeros(buffer.open_length, bool))
    if not rows:
        empty = np.zeros(0, dtype=np.int64)
        return empty, np.zeros((0, buffer.tile_coder.n_tilings), np.int64), np.zeros(0, bool)
    return np.concatenate(rows), np.vstack(next_slots), np.concatenate(terminal)


def target_comparison(model, sigma: str = "average_worst") -> dict[str, np.ndarray]:
    """Every stored transition's Q(s_t, a_t), vanilla target and ER-sigma target (with `sigma`'s definition) on the
    model's current weights and visits; columns :data:`COMPARISON_COLUMNS` as arrays. Targets are greedy
    (max over a'), so nothing random enters; the model is not changed.

    :param model: the trained ER-family model.
    :param sigma: sigma's definition (default "average_worst").
    """
    from sb3_er.er import SIGMAS

    buffer, coder, policy = model.replay_buffer, model.policy.tile_coder, model.policy
    rows, next_slots, terminal = stored_transitions(buffer)
    out = np.zeros((rows.size, len(COMPARISON_COLUMNS)))
    q = np.zeros(coder.n_actions)
    w = np.zeros(coder.n_actions)
    # the stored rows, oldest first, as a Trajectories bundle of their own (the target reads s, a, r and w)
    no_rows = np.zeros(0, dtype=np.int64)
    data = kernels.make(
        kernels.Trajectories,
        visits=buffer.visits,
        slots=np.ascontiguousarray(buffer.slots[rows]),
        actions=np.ascontiguousarray(buffer.actions[rows]),
        rewards=np.ascontiguousarray(buffer.rewards[rows]),
        transition_trajectory=no_rows,
        trajectory_start=no_rows,
        trajectory_length=no_rows,
        trajectory_terminated=np.zeros(0, dtype=bool),
        trajectory_next_slots=np.zeros((0, coder.n_tilings), dtype=np.int64),
        oldest_trajectory=0,
        n_closed_trajectories=0,
        first_row=0,
        n_transitions=rows.size,
        open_trajectory=-1,
        open_start=0,
        open_length=0,
        open_next_slots=np.zeros(coder.n_tilings, dtype=np.int64),
    )
    rule = kernels.update_rule(0.0, model.gamma, target_kind=kernels.TARGET_Q_LEARNING, sigma_kind=SIGMAS[sigma])
    _compare_targets(policy.weights, data, next_slots, terminal, coder.layout, rule, kernels.Scratch(q, w), out)
    result = {name: out[:, i] for i, name in enumerate(COMPARISON_COLUMNS)}
    result["terminal"] = result["terminal"].astype(bool)
    result["no_action_visited"] = result["no_action_visited"].astype(bool)
    result["n_tilings"] = coder.n_tilings
    return result


def comparison_summary(comparison: dict[str, np.ndarray]) -> dict[str, float]:
    """Figures of one :func:`target_comparison` over the non-terminal transitions: mean Q(s, a), mean vanilla and
    sigma targets, the shares of targets sigma raises and lowers, the mean raise relative to mean |Q(s, a)|, the share
    where sigma's a' is not fully visited, where no action at s' was visited, and the mean shared share of tiles.

    :param comparison: a result of :func:`target_comparison`.
    """
    keep = ~comparison["terminal"]
    if not keep.any():
        return {}
    q_sa = comparison["q_sa"][keep]
    vanilla, sigma = comparison["target_vanilla"][keep], comparison["target_sigma"][keep]
    scale = max(float(np.abs(q_sa).mean()), 1e-12)
    tolerance = 1e-9 * max(scale, 1.0)
    return {
        "transitions": int(keep.sum()),
        "mean_q_sa": float(q_sa.mean()),
        "max_q_sa": float(q_sa.max()),
        "mean_target_vanilla": float(vanilla.mean()),
        "mean_target_sigma": float(sigma.mean()),
        "share_raised": float((sigma > vanilla + tolerance).mean()),
        "share_lowered": float((sigma < vanilla - tolerance).mean()),
        "mean_shift_relative": float((sigma - vanilla).mean() / scale),
        "mean_excess_sigma_relative": float((sigma - q_sa).mean() / scale),
        "mean_excess_vanilla_relative": float((vanilla - q_sa).mean() / scale),
        "share_partly_visited_choice": float((comparison["w_chosen"][keep] < comparison["n_tilings"]).mean()),
        "share_no_action_visited": float(comparison["no_action_visited"][keep].mean()),
        "mean_overlap_vanilla": float(comparison["overlap_vanilla"][keep].mean()),
        "mean_overlap_sigma": float(comparison["overlap_sigma"][keep].mean()),
    }


def replay_gain(
    model,
    n_phases: int = 30,
    n_trajectories: int | None = None,
    sigma: str | None = "keep",
    skip: int = 10,
    seed: int = 1,
) -> float:
    """The growth factor per replay phase of the replay operator on `model`'s stored data with every reward 0.

    Replays ``n_phases`` phases of `n_trajectories` (default: the model's own per phase) from the model's weights,
    rewards set to 0, ``sigma`` the model's own ("keep") or another definition (None: vanilla), unseen by the value
    watch; returns (m_end / m_skip)^(1 / (n_phases - skip)) for m the mean over stored states of max_a Q(s, a) in
    magnitude. The model's weights, sigma, rewards, generators, counters and watch are restored afterwards.

    :param model: the trained ER-family model (restored afterwards).
    :param n_phases: replay phases (default 30).
    :param n_trajectories: trajectories per phase (default None: the model's own).
    :param sigma: see above (default "keep").
    :param skip: phases left out at the start (default 10).
    :param seed: the seed of the replay generator (default 1).
    """
    buffer = model.replay_buffer
    rows, _, _ = stored_transitions(buffer)
    observations = buffer.observations[rows]
    theta = model.policy.theta_array
    saved_theta, saved_rewards, saved_sigma = theta.copy(), buffer.rewards.copy(), model.sigma
    saved_replay_rng, saved_action_rng = model.replay_rng.copy(), model.action_rng.copy()
    saved_counts = (model.replay_updates, model.replay_phases, model._td_error_sum, model._td_error_count)
    watch = model._watch.array
    saved_watch = watch.copy()  # the value watch does not keep what it sees of these replays
    per_phase = n_trajectories if n_trajectories is not None else model._replays_per_phase()
    try:
        buffer.rewards[:] = 0.0
        if sigma != "keep":
            model.sigma = sigma
        model.seed_replay(seed)
        sizes = []
        for _ in range(n_phases):
            model.replay(per_phase)
            sizes.append(float(np.abs(model.policy.q_values(observations).max(axis=1)).mean()))
    finally:
        theta[:] = saved_theta
        buffer.rewards[:] = saved_rewards
        model.sigma = saved_sigma
        model.replay_rng[:], model.action_rng[:] = saved_replay_rng, saved_action_rng
        model.replay_updates, model.replay_phases, model._td_error_sum, model._td_error_count = saved_counts
        watch[:] = saved_watch
    return (sizes[-1] / sizes[skip - 1]) ** (1.0 / (n_phases - skip))
