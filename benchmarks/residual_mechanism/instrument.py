"""Instrumented residual-ER replay on copies of a model's weights and buffer (read-only on the package).

`instrumented_phase(model, n_trajectories, seed)` re-implements one replayed update of sb3_er's kernel
(`kernels.replay_update`, sigma none, sarsa target) in NumPy on a *copy* of theta, replaying `n_trajectories`
trajectories drawn uniformly from the closed ones, each from its last sample to its first, and records per update:
delta, the actions (a_k, the epsilon-greedy a' drawn at s_{k+1}, the stored a_{k+1}), the overlaps of phi(s_{k+1}, b)
with phi(s_k, a_k) and the actual changes of Q(s_{k+1}, .) and Q(s_k, a_k). The plain-ER counterfactual for the same
theta and the same delta is computed analytically (plain ER adds step*delta to the weights of phi(s_k, a_k) only).
The model itself (weights, buffer, generators) is never touched.
"""

from __future__ import annotations

import numpy as np

from sb3_er.common import kernels


def _overlap(idx_a: np.ndarray, idx_b: np.ndarray) -> int:
    """sum over entries of idx_b of how often they occur in idx_a: phi_a . phi_b for binary multiset features."""
    return int((idx_a[:, None] == idx_b[None, :]).sum())


def numpy_update(
    theta, slots_s, a, r, slots_s1, terminal, stride, n_actions, zeta, next_action_mode, step, gamma, epsilon, rng
):
    """One replayed (residual) ER update on theta in place, as kernels.replay_update; returns a dict of measurements."""
    idx_sa = slots_s * stride + a
    q_sa = theta[idx_sa].sum()
    rec = {"a_k": a, "terminal": terminal}
    if terminal:
        target = r
        a_eps = -1
        q1_before = None
    else:
        rows = slots_s1[:, None] * stride + np.arange(n_actions)[None, :]  # (N, A) weight indices at s'
        q1_before = theta[rows].sum(axis=0)
        a_eps = int(kernels.epsilon_greedy(q1_before.copy(), epsilon, rng))
        target = r + gamma * q1_before[a_eps]
    delta = target - q_sa
    rec["delta"] = delta
    rec["a_eps"] = a_eps
    res_action = a if (terminal or next_action_mode == "taken") else a_eps
    rec["a_res"] = res_action
    # the update
    theta_before_sa = q_sa
    np.add.at(theta, idx_sa, step * delta)
    if zeta > 0.0 and not terminal:
        idx_res = slots_s1 * stride + res_action
        np.add.at(theta, idx_res, -step * delta * zeta * gamma)
    rec["dq_sa"] = theta[idx_sa].sum() - theta_before_sa
    if not terminal:
        q1_after = theta[rows].sum(axis=0)
        rec["q1_before"] = q1_before
        rec["dq1"] = q1_after - q1_before
        rec["overlap"] = np.array([_overlap(idx_sa, rows[:, b]) for b in range(n_actions)])  # phi(s,a_k).phi(s',b)
        rec["greedy_before"] = int(np.argmax(q1_before))
        rec["greedy_after"] = int(np.argmax(q1_after))
    return rec


def instrumented_phase(model, n_trajectories: int, seed: int, max_updates: int | None = None):
    """Replay n_trajectories of model's closed trajectories on a copy of theta; returns a dict of per-update arrays."""
    buffer = model.replay_buffer
    coder = model.policy.tile_coder
    assert coder.columns_are_actions and model.sigma is None and model.target == "sarsa"
    assert tuple(model.policy.initial_arguments[:2]) == (0.0, 0.0)
    theta = model.policy.theta_array.copy()
    stride, n_actions, n_tilings = coder.stride, coder.n_actions, coder.n_tilings
    zeta = 0.0 if model.residual_zeta is None else float(model.residual_zeta)
    mode = model.residual_action
    step = model.current_learning_rate / n_tilings
    gamma, epsilon = model.gamma, model.exploration_rate
    rng = kernels.new_rng_state(seed, kernels.RNG_STREAM_ACTIONS)
    picks = np.random.default_rng(seed)
    cap = buffer.capacity
    n_closed = buffer.n_trajectories
    assert n_closed > 0
    out = {
        key: []
        for key in (
            "delta",
            "terminal",
            "a_k",
            "a_eps",
            "a_stored",
            "a_res",
            "dq_sa",
            "dq1",
            "overlap",
            "greedy_before",
            "greedy_after",
            "q1_before",
            "r",
        )
    }
    n = 0
    for _ in range(n_trajectories):
        j = (buffer.oldest_trajectory + int(picks.integers(n_closed))) % cap
        start, length = int(buffer.trajectory_start[j]), int(buffer.trajectory_length[j])
        for t in range(length - 1, -1, -1):
            p = (start + t) % cap
            last = t == length - 1
            slots_s1 = buffer.trajectory_next_slots[j] if last else buffer.slots[(p + 1) % cap]
            terminal = bool(buffer.trajectory_terminated[j]) if last else False
            a_stored = -1 if last else int(buffer.actions[(p + 1) % cap])
            rec = numpy_update(
                theta,
                buffer.slots[p],
                int(buffer.actions[p]),
                float(buffer.rewards[p]),
                slots_s1,
                terminal,
                stride,
                n_actions,
                zeta,
                mode,
                step,
                gamma,
                epsilon,
                rng,
            )
            if terminal:
                continue  # no s_{k+1} term; not counted
            out["a_stored"].append(a_stored)
            out["r"].append(float(buffer.rewards[p]))
            for key in (
                "delta",
                "terminal",
                "a_k",
                "a_eps",
                "a_res",
                "dq_sa",
                "dq1",
                "overlap",
                "greedy_before",
                "greedy_after",
                "q1_before",
            ):
                out[key].append(rec[key])
            n += 1
            if max_updates is not None and n >= max_updates:
                break
        if max_updates is not None and n >= max_updates:
            break
    res = {key: np.array(value) for key, value in out.items()}
    res.update(n_tilings=n_tilings, step=step, gamma=gamma, zeta=zeta, mode=mode, alpha=step * n_tilings)
    return res


def verify_against_kernel(model, n_updates: int = 300, seed: int = 7) -> float:
    """Max |theta difference| between numpy_update and kernels.replay_update over the first updates of a trajectory,
    both from the same theta and the same generator state (sarsa target, no sigma)."""
    buffer = model.replay_buffer
    coder = model.policy.tile_coder
    theta_np = model.policy.theta_array.copy()
    theta_k = theta_np.copy()
    zeta = 0.0 if model.residual_zeta is None else float(model.residual_zeta)
    step = model.current_learning_rate / coder.n_tilings
    rng_np = kernels.new_rng_state(seed, 0)
    rng_k = rng_np.copy()
    q = np.zeros(coder.n_actions)
    w = np.zeros(coder.n_actions)
    j = buffer.oldest_trajectory
    start, length = int(buffer.trajectory_start[j]), int(buffer.trajectory_length[j])
    worst = 0.0
    for i, t in enumerate(range(length - 1, -1, -1)):
        if i >= n_updates:
            break
        p = start + t
        last = t == length - 1
        slots_s1 = buffer.trajectory_next_slots[j] if last else buffer.slots[p + 1]
        terminal = bool(buffer.trajectory_terminated[j]) if last else False
        numpy_update(
            theta_np,
            buffer.slots[p],
            int(buffer.actions[p]),
            float(buffer.rewards[p]),
            slots_s1,
            terminal,
            coder.stride,
            coder.n_actions,
            zeta,
            model.residual_action,
            step,
            model.gamma,
            model.exploration_rate,
            rng_np,
        )
        kernels.replay_update(
            theta_k,
            buffer.visits,
            buffer.slots,
            buffer.actions,
            buffer.rewards,
            p,
            np.ascontiguousarray(slots_s1),
            terminal,
            coder.stride,
            coder.action_columns,
            coder.columns_are_actions,
            kernels.TARGET_SARSA,
            kernels.SIGMA_NONE,
            zeta,
            model.residual_action == "next",
            step,
            model.gamma,
            model.exploration_rate,
            rng_k,
            q,
            w,
            0.0,
            0.0,
            np.uint64(0),
            kernels.NO_WATCH,
        )
        worst = max(worst, float(np.abs(theta_np - theta_k).max()))
        assert (rng_np == rng_k).all()
    return worst


def summarize(res: dict) -> dict:
    """Aggregate per-update measurements into the figures of the report."""
    n = res["n_tilings"]
    gamma, zeta = res["gamma"], res["zeta"]
    delta = res["delta"]
    m = delta.shape[0]
    idx = np.arange(m)
    a_k, a_eps, a_st, a_res = res["a_k"], res["a_eps"], res["a_stored"], res["a_res"]
    ov = res["overlap"]  # (m, A): phi(s_k,a_k).phi(s_{k+1}, b)
    has_st = a_st >= 0
    share_k = ov[idx, a_k] / n
    share_eps = ov[idx, a_eps] / n
    share_st = np.where(has_st, ov[idx, np.maximum(a_st, 0)] / n, np.nan)
    alpha = res["alpha"]
    ad = alpha * delta
    nz = np.abs(ad) > 1e-12
    dq1 = res["dq1"]  # actual change of Q(s', .) under this run's rule
    plain_dq1 = (res["step"] * delta)[:, None] * ov  # plain ER on the same theta and delta
    out = {
        "updates": m,
        "mean_abs_delta": float(np.abs(delta).mean()),
        "frac_delta_neg": float((delta < 0).mean()),
        "frac_r_neg": float((res["r"] < 0).mean()),
        # (a) tile sharing
        "share_ak": float(share_k.mean()),
        "share_ak_q10_q50_q90": tuple(np.round(np.quantile(share_k, [0.1, 0.5, 0.9]), 3)),
        "share_aeps": float(share_eps.mean()),
        "share_astored": float(np.nanmean(share_st)),
        "share_ak_when_same_eps": float(share_k[a_eps == a_k].mean()) if (a_eps == a_k).any() else np.nan,
        # (c) action repeats
        "p_aeps_eq_ak": float((a_eps == a_k).mean()),
        "p_astored_eq_ak": float((a_st[has_st] == a_k[has_st]).mean()),
        "p_aeps_eq_astored": float((a_eps[has_st] == a_st[has_st]).mean()),
        # (b) effect sizes in units of alpha*delta (signed mean over updates with delta != 0)
        "dQ(s',a_k)/ad plain": float((plain_dq1[idx, a_k][nz] / ad[nz]).mean()),
        "dQ(s',a_k)/ad rule": float((dq1[idx, a_k][nz] / ad[nz]).mean()),
        "dQ(s',a_eps)/ad plain": float((plain_dq1[idx, a_eps][nz] / ad[nz]).mean()),
        "dQ(s',a_eps)/ad rule": float((dq1[idx, a_eps][nz] / ad[nz]).mean()),
        "dQ(s,a_k)/ad rule": float((res["dq_sa"][nz] / ad[nz]).mean()),
        "mean|dQ(s',a_k)| plain": float(np.abs(plain_dq1[idx, a_k]).mean()),
        "mean|dQ(s',a_k)| rule": float(np.abs(dq1[idx, a_k]).mean()),
        "mean|dQ(s',a_eps)| plain": float(np.abs(plain_dq1[idx, a_eps]).mean()),
        "mean|dQ(s',a_eps)| rule": float(np.abs(dq1[idx, a_eps]).mean()),
        "mean|dQ(s,a_k)| plain": float(np.abs(ad).mean()),
        "mean|dQ(s,a_k)| rule": float(np.abs(res["dq_sa"]).mean()),
    }
    if zeta > 0:
        res_term = -(res["step"] * delta) * zeta * gamma * n  # change of Q(s', a_res) by the residual term alone
        raises = res_term > 0
        not_taken_next = has_st & (a_res != a_st)
        out.update(
            {
                "frac_resterm_raises_Q(s',a_res)": float(raises.mean()),
                "frac_resterm_raises_non_taken_next": float((raises & not_taken_next).sum() / has_st.sum()),
                "frac_net_raise_Q(s',a_res)": float((dq1[idx, a_res] > 0).mean()),
                "frac_net_raise_non_taken_next": float(((dq1[idx, a_res] > 0) & not_taken_next).sum() / has_st.sum()),
                "frac_plain_raise_Q(s',a_res)": float((plain_dq1[idx, a_res] > 0).mean()),
                "frac_a_res_ne_greedy_before": float((a_res != res["greedy_before"]).mean()),
                "frac_greedy_flips_to_a_res": float(
                    ((res["greedy_before"] != a_res) & (res["greedy_after"] == a_res)).mean()
                ),
                "mean_resterm_abs": float(np.abs(res_term).mean()),
            }
        )
    return out
