"""Bundles for the tests that call the kernels directly (sb3_er.common.kernels.bundles), with the tests' defaults."""

import numpy as np

from sb3_er.common import kernels


def weights(theta: np.ndarray, initial=kernels.ZERO_INITIAL, target=None) -> kernels.Weights:
    low, span, seed = initial
    return kernels.weights_bundle(theta, low, span, seed, target)


def rule(
    step_size: float,
    gamma: float,
    epsilon: float = 0.0,
    target=kernels.TARGET_SARSA,
    sigma=kernels.SIGMA_NONE,
    zeta: float = 0.0,
    residual_next_action: bool = False,
    truncate=None,
    step_bound: bool = False,
    step_cap=None,
    averager: bool = False,
    project: bool = False,
) -> kernels.UpdateRule:
    """An UpdateRule; ``truncate`` is None (off) or the (low, high) of the possible returns, which ``project`` (a
    bool) needs too."""
    low, high = (-np.inf, np.inf) if truncate is None else truncate
    return kernels.update_rule(
        step_size,
        gamma,
        epsilon,
        target_kind=target,
        sigma_kind=sigma,
        residual_zeta=zeta,
        residual_next_action=residual_next_action,
        truncate=truncate is not None,
        value_low=low,
        value_high=high,
        step_bound=step_bound,
        step_cap=step_cap,
        averager=averager,
        project=project,
    )


def replay(n_trajectories: int = 1, order=kernels.ORDER_REVERSED, picks_rng=None, max_updates=-1) -> kernels.Replay:
    picks_rng = kernels.new_rng_state(0, kernels.RNG_STREAM_REPLAY) if picks_rng is None else picks_rng
    return kernels.make(
        kernels.Replay, n_trajectories=n_trajectories, max_updates=max_updates, order=order, picks_rng=picks_rng
    )


def scratch(n_actions: int) -> kernels.Scratch:
    return kernels.Scratch(np.zeros(n_actions), np.zeros(n_actions))


def trace(n_weights: int, capacity: int, decay: float, cutoff: float) -> kernels.Trace:
    return kernels.make(
        kernels.Trace,
        index=np.zeros(capacity, np.int64),
        value=np.zeros(capacity),
        position=np.full(n_weights, -1, np.int32),
        length=np.zeros(1, np.int64),
        decay=decay,
        cutoff=cutoff,
    )


def replay_phase(
    theta,
    buffer,
    rule_: kernels.UpdateRule,
    n_trajectories: int = 1,
    order=kernels.ORDER_REVERSED,
    initial=kernels.ZERO_INITIAL,
    watch=kernels.NO_WATCH,
    picks_rng=None,
    data=None,
    target=None,
    max_updates=-1,
):
    """One replay phase on ``buffer`` (its Trajectories unless ``data`` is given) with fresh seeded generators."""
    coder = buffer.tile_coder
    return kernels.replay_phase(
        weights(theta, initial, target),
        buffer.replay_data() if data is None else data,
        coder.layout,
        rule_,
        replay(n_trajectories, order, picks_rng, max_updates),
        kernels.new_rng_state(0, kernels.RNG_STREAM_ACTIONS),
        scratch(coder.n_actions),
        watch,
    )
