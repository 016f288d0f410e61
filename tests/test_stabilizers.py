"""The replay stabilizers, each against its guarantee on a hand case (issue 34): truncation (with and without the
target copy) keeps Figure 5.6's self-affecting sample inside the possible returns for every ER variant, where the
literal algorithms leave them; the target copy is read by bootstrapping and taken anew at each phase; the step-size
bound stops a step that would carry a transition's TD error past zero; the averager moves Q(s, a) as far as the
semi-gradient step but keeps every value inside the range of its start and its targets, without truncation; the
projection keeps every weight an update moved inside the possible returns / N; the replay ratio bounds the updates per
new sample; presets resolve with explicit arguments winning."""

import kernel_bundles as bundles
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sb3_cases import InMemoryLogger

from sb3_er import ER, ERSigma, ResidualER, ResidualERSigma
from sb3_er.common import kernels
from sb3_er.common.buffers import TrajectoryReplayBuffer
from sb3_er.common.tile_coding import TileCoder
from sb3_er.er import PRESETS, resolve_preset
from sb3_er.experiments import value_growth as vg


def _possible(case: str) -> tuple[float, float]:
    """Figure 5.6's possible returns by hand: the sample pays r forever, r / (1 - gamma), hulled with the values the
    weights start at (Q(s', a) initially, and Q(s, a) initially)."""
    values = vg.CASES[case]
    returns = values["reward"] / (1.0 - vg.FIGURE_GAMMA)
    start = (values["q_next"], values["q_state"])
    return min(returns, *start), max(returns, *start)


@pytest.mark.parametrize("variant", list(vg.VARIANTS))
@pytest.mark.parametrize("case", list(vg.CASES))
@pytest.mark.parametrize("target_copy", [False, True])
def test_truncation_keeps_the_self_affecting_sample_inside_the_possible_returns(variant, case, target_copy):
    low, high = _possible(case)
    literal = vg.replay_values(vg.self_affecting_model(variant, case, shared=3), 400)
    stable = vg.replay_values(
        vg.self_affecting_model(variant, case, shared=3, truncate_targets=True, target_copy=target_copy), 400
    )
    tolerance = 1e-9 * max(abs(low), abs(high))
    assert np.all((stable >= low - tolerance) & (stable <= high + tolerance)), (stable.min(), stable.max())
    if case == "b" and variant in ("ER", "ER-σ"):  # the literal sample leaves them (thesis 5.3.1): it can fail
        assert literal.max() > high


def test_the_target_copy_is_read_by_bootstrapping_and_refreshed_per_phase():
    """With a target copy, a phase bootstraps from the weights as they were when it began: replaying the chain
    0 -> 1 -> 2 -> (terminal, reward 10) reversed, with alpha 1 and gamma 1, backs the reward up one step per phase
    instead of to the start in one pass (thesis 4.1's reversed replay, whose speed the copy gives up)."""
    coder = TileCoder([1.0], [1], n_tilings=1, memory_size=2**12)
    buffer = TrajectoryReplayBuffer(100, coder)
    for s, r in zip([0, 1, 2], [0.0, 0.0, 10.0], strict=True):
        end = True if s == 2 else None
        buffer.add(np.array([float(s)]), coder.slots(np.array([float(s)])), 0, r, np.array([s + 1.0]), end=end)
    values = lambda theta: [theta[coder.feature_indices(np.array([float(s)]), 0)].sum() for s in range(3)]  # noqa: E731
    plain = np.zeros(coder.n_weights)
    bundles.replay_phase(plain, buffer, bundles.rule(1.0, 1.0))
    assert values(plain) == [10.0, 10.0, 10.0]
    theta = np.zeros(coder.n_weights)
    copy = kernels.TargetCopy(theta)
    seen = []
    for _ in range(3):
        kernels.refresh_target(bundles.weights(theta, target=copy))
        bundles.replay_phase(theta, buffer, bundles.rule(1.0, 1.0), target=copy)
        seen.append(values(theta))
    assert seen == [[0.0, 0.0, 10.0], [0.0, 10.0, 10.0], [10.0, 10.0, 10.0]]
    assert copy.n_changed[0] == 3 and np.array_equal(np.flatnonzero(copy.changed_flag), np.sort(copy.changed[:3]))


def _one_step(alpha: float, step_bound: bool, cap: np.ndarray):
    """One replayed update of (s = 0.5, r = 1, s' = 3.5, never visited) with N = 4 tilings: Q(s, a) = 0 -> the
    target 1 + gamma Q(s', a') = 1. Returns the TD error of the same transition after the update."""
    coder = TileCoder([1.0], [1], n_tilings=4, memory_size=2**12)
    buffer = TrajectoryReplayBuffer(10, coder)
    buffer.add(np.array([0.5]), coder.slots(np.array([0.5])), 0, 1.0, np.array([3.5]), end=True)
    theta = np.zeros(coder.n_weights)
    update = bundles.rule(alpha / 4, 0.9, step_bound=step_bound, step_cap=cap)
    bundles.replay_phase(theta, buffer, update)
    return 1.0 - theta[coder.feature_indices(np.array([0.5]), 0)].sum()


def test_the_step_size_bound_stops_an_overshoot():
    """alpha 1.5 > 1: the plain step carries Q(s, a) past its target (the TD error 1 becomes 1 - 1.5 = -0.5);
    Dabney and Barto's bound, 1 / |phi^T phi| = 1 / 4 per weight at a terminal transition, makes it exactly 0, and
    keeps that bound for the rest of the run."""
    assert _one_step(1.5, False, np.full(1, np.inf)) == pytest.approx(-0.5)
    cap = np.full(1, np.inf)
    assert _one_step(1.5, True, cap) == pytest.approx(0.0, abs=1e-12)
    assert cap[0] == pytest.approx(1 / 4)
    assert _one_step(0.5, True, np.full(1, np.inf)) == pytest.approx(0.5)  # alpha <= 1: it does not bind


def test_the_step_size_bound_with_a_trace():
    """Sarsa(lambda) with replacing traces: s0 -> s1 -> s0, one tiling each, disjoint. At the second step the trace
    holds phi(s0) gamma lambda and phi(s1) = 1, and s' = s0: (gamma phi' - phi)^T e = gamma (gamma lambda) - 1, by
    hand, so the bound is 1 / (1 - gamma^2 lambda) per weight, looser than without the trace (1)."""
    coder = TileCoder([1.0], [1], n_tilings=1, memory_size=2**12)
    gamma, lam = 0.9, 0.5
    theta = np.zeros(coder.n_weights)
    trace = tuple(bundles.trace(coder.n_weights, 16, decay=gamma * lam, cutoff=1e-9))
    cap = np.full(1, np.inf)
    rule = tuple(bundles.rule(5.0, gamma, step_bound=True, step_cap=cap))
    for s, s_next in ((0.5, 1.5), (1.5, 0.5)):
        transition = (coder.slots(np.array([s])), 0, 0.0, False, np.array([s_next]), np.zeros(1, np.int64))
        kernels.sarsa_lambda_step(
            tuple(bundles.weights(theta)),
            trace,
            tuple(coder.layout),
            rule,
            transition,
            kernels.new_rng_state(0),
            tuple(bundles.scratch(1)),
            kernels.NO_WATCH,
        )
        if s == 0.5:
            assert cap[0] == pytest.approx(1.0)  # first step: e = phi(s0), phi' = phi(s1): |0 - 1| = 1
    assert cap[0] == pytest.approx(1.0)  # the second step's bound, 1 / (1 - 0.405), is looser: the cap stays 1
    assert 1.0 / (1.0 - gamma * gamma * lam) > 1.0


def test_the_averager_step_by_hand():
    """One replayed update of a terminal transition (r = 2) from s, whose N = 4 weights are 1, 2, 3, 4 (Q = 10), with
    alpha 0.5: the semi-gradient adds alpha delta / N = 0.125 (2 - 10) = -1 to each (0, 1, 2, 3); the averager moves
    each halfway to T / N = 0.5 (0.75, 1.25, 1.75, 2.25). Both give Q(s, a) = 10 + 0.5 (2 - 10) = 6."""
    coder = TileCoder([1.0], [1], n_tilings=4, memory_size=2**12)
    buffer = TrajectoryReplayBuffer(10, coder)
    state = np.array([0.5])
    buffer.add(state, coder.slots(state), 0, 2.0, np.array([3.5]), end=True)
    features = coder.feature_indices(state, 0)
    assert np.unique(features).size == 4
    moved = {}
    for averager in (False, True):
        theta = np.zeros(coder.n_weights)
        theta[features] = [1.0, 2.0, 3.0, 4.0]
        bundles.replay_phase(theta, buffer, bundles.rule(0.5 / 4, 0.9, averager=averager))
        moved[averager] = theta[features]
    assert np.allclose(moved[False], [0.0, 1.0, 2.0, 3.0])
    assert np.allclose(moved[True], [0.75, 1.25, 1.75, 2.25])
    assert moved[False].sum() == pytest.approx(6.0) and moved[True].sum() == pytest.approx(6.0)


@pytest.mark.parametrize("variant", ["ER", "ER-σ"])
@pytest.mark.parametrize("case", list(vg.CASES))
def test_the_averager_keeps_the_self_affecting_sample_inside_without_truncation(variant, case):
    """Figure 5.6's sample, which the literal semi-gradient variants carry out of the possible returns (case b), stays
    inside them with the averager alone: no truncation, no target copy."""
    low, high = _possible(case)
    stable = vg.replay_values(vg.self_affecting_model(variant, case, shared=3, averager=True), 400)
    tolerance = 1e-9 * max(abs(low), abs(high))
    assert np.all((stable >= low - tolerance) & (stable <= high + tolerance)), (stable.min(), stable.max())
    literal = vg.replay_values(vg.self_affecting_model(variant, case, shared=3), 400)
    if case == "b":
        assert literal.max() > high


def test_the_projection_by_hand():
    """A terminal transition (r = 10) from s, whose N = 4 weights are 0, 0, 0, 4 (Q = 4), alpha 1, values bounded to
    [-10, 10]: the semi-gradient step adds (10 - 4) / 4 = 1.5 to each (1.5, 1.5, 1.5, 5.5; Q = 10, inside the bounds);
    the projection then clips the last weight to 10 / 4 = 2.5 (Q = 7): it bounds each weight, not only their sum, which
    is the representation it gives up."""
    coder = TileCoder([1.0], [1], n_tilings=4, memory_size=2**12)
    buffer = TrajectoryReplayBuffer(10, coder)
    state = np.array([0.5])
    buffer.add(state, coder.slots(state), 0, 10.0, np.array([3.5]), end=True)
    features = coder.feature_indices(state, 0)
    moved = {}
    for project in (False, True):
        theta = np.zeros(coder.n_weights)
        theta[features] = [0.0, 0.0, 0.0, 4.0]
        bundles.replay_phase(theta, buffer, bundles.rule(1.0 / 4, 0.9, truncate=(-10.0, 10.0), project=project))
        moved[project] = theta[features]
    assert np.allclose(moved[False], [1.5, 1.5, 1.5, 5.5])
    assert np.allclose(moved[True], [1.5, 1.5, 1.5, 2.5])


@pytest.mark.parametrize("variant", list(vg.VARIANTS))
@pytest.mark.parametrize("case", list(vg.CASES))
def test_the_projection_keeps_the_self_affecting_sample_inside_for_every_variant(variant, case):
    """Figure 5.6's sample with the projection alone (no truncation, no target copy), residual variants included."""
    low, high = _possible(case)
    stable = vg.replay_values(vg.self_affecting_model(variant, case, shared=3, project_weights=True), 400)
    tolerance = 1e-9 * max(abs(low), abs(high))
    assert np.all((stable >= low - tolerance) & (stable <= high + tolerance)), (stable.min(), stable.max())


@settings(max_examples=30, deadline=None)
@given(
    rewards=st.lists(st.floats(-1.0, 1.0), min_size=2, max_size=12),
    moves=st.lists(st.floats(-0.6, 0.6), min_size=12, max_size=12),
    alpha=st.floats(0.05, 1.0),
    gamma=st.floats(0.5, 0.99),
    sigma=st.sampled_from([kernels.SIGMA_NONE, kernels.SIGMA_AVERAGE_WORST, kernels.SIGMA_BEST]),
    start=st.floats(-1.0, 1.0),
    stabilizer=st.sampled_from(["averager", "project", "project residual"]),
)
def test_averager_and_projection_keep_every_value_inside_the_possible_returns(
    rewards, moves, alpha, gamma, sigma, start, stabilizer
):
    """Their guarantees on random trajectories of a 1-D walk with 2 actions and overlapping tiles: rewards in [-1, 1]
    and every weight starting at start / ((1 - gamma) N) keep every weight of the table, times N, inside
    [-1 / (1 - gamma), 1 / (1 - gamma)] through 20 replay phases, for ER and each sigma of ER-sigma (and with the
    projection, their residual variants); so every Q(s, a) and every sigma-extrapolated Q~ are inside too. Gordon's
    (1995) averager needs no bounds for it; the projection is given them."""
    coder = TileCoder([0.7], [2], n_tilings=4, memory_size=2**12)
    buffer = TrajectoryReplayBuffer(100, coder)
    bound = 1.0 / (1.0 - gamma)
    state = np.array([0.0])
    for t, reward in enumerate(rewards):
        next_state = np.clip(state + moves[t], -3.0, 3.0)
        end = True if t == len(rewards) - 1 else None
        buffer.add(state, coder.slots(state), t % 2, reward, next_state, end=end)
        state = next_state
    theta = np.full(coder.n_weights, start * bound / 4)
    if stabilizer == "averager":
        rule = bundles.rule(alpha / 4, gamma, 0.1, sigma=sigma, averager=True)
    else:
        zeta = 1.0 if stabilizer == "project residual" else 0.0
        rule = bundles.rule(alpha / 4, gamma, 0.1, sigma=sigma, zeta=zeta, truncate=(-bound, bound), project=True)
        rule = rule._replace(truncate=False)  # the projection alone, given the bounds
    for phase in range(20):
        bundles.replay_phase(theta, buffer, rule, picks_rng=kernels.new_rng_state(phase, 1))
    assert np.all(np.abs(theta * 4) <= bound * (1 + 1e-9)), (theta.min() * 4, theta.max() * 4, bound)


def test_the_averager_refuses_what_it_cannot_bound():
    """The residual direction has no averager form; a learning rate above 1 carries weights past their targets. A
    preset's averager is dropped on the residual classes, which keep the preset's other stabilizers."""
    with pytest.raises(ValueError, match="averager=True with residual_zeta=1.0"):
        ResidualER("TileQ", "CartPole-v1", averager=True)
    with pytest.raises(ValueError, match="averager=True with residual_zeta=0.5"):
        ER("TileQ", "CartPole-v1", averager=True, residual_zeta=0.5)
    with pytest.raises(ValueError, match="averager=True needs a learning rate of at most 1"):
        ERSigma("TileQ", "CartPole-v1", averager=True, learning_rate=1.5)
    # a schedule that passes 1 later in the run is refused when the model is built, not in the middle of learn
    with pytest.raises(ValueError, match="1.5 at progress_remaining 0.00 of its schedule"):
        ERSigma("TileQ", "CartPole-v1", averager=True, learning_rate=lambda remaining: 0.5 + (1.0 - remaining))
    assert ER("TileQ", "CartPole-v1", averager=True, residual_zeta=0.0).stabilizers["averager"] is True


def test_a_preset_averager_is_dropped_by_the_residual_classes(monkeypatch):
    monkeypatch.setitem(PRESETS, "stable", {**PRESETS["stable"], "averager": True, "truncate_targets": True})
    for algo in (ResidualER, ResidualERSigma):
        model = algo("TileQ", "CartPole-v1", preset="stable")
        assert model.stabilizers["averager"] is False and model.stabilizers["truncate_targets"] is True
    assert ERSigma("TileQ", "CartPole-v1", preset="stable").stabilizers["averager"] is True


@pytest.mark.parametrize("algo", [ERSigma, ResidualERSigma])
def test_the_stable_preset_keeps_pendulum_values_inside_where_the_literal_leaves(algo):
    """Pendulum-v1, where the literal ER-sigma's values leave the possible returns within its first 15,000 steps (the
    screen's runs go on to 1e205): the stable preset, the projection, keeps every value inside, up to rounding."""
    literal = algo("TileQ", "Pendulum-v1", seed=0, value_bound_action="ignore").learn(15_000)
    assert literal.values_out_of_range > 0
    stable = algo("TileQ", "Pendulum-v1", seed=0, preset="stable").learn(15_000)
    assert stable.stabilizers["project_weights"] is True
    assert stable.values_out_of_range == 0 and stable.largest_excursion <= 1e-9 * 1700


def test_tensorboard_shows_how_often_truncation_and_projection_bind():
    """train/truncated_share and train/projected_share: shares of the period's updates, in [0, 1], each logged only
    with its stabilizer; on Pendulum-v1 both bind (the literal ER-sigma's values leave the bounds there)."""
    logged = {}
    for option in ("truncate_targets", "project_weights"):
        model = ERSigma("TileQ", "Pendulum-v1", seed=0, preset="thesis", value_bound_action="ignore", **{option: True})
        logger = InMemoryLogger()
        model.set_logger(logger)
        model.learn(6_000, log_interval=1)
        logged[option] = [dump for dump in logger.dumped if "train/replay_ratio" in dump]
        assert logged[option], "no train/ dump"
    truncated = [dump.get("train/truncated_share") for dump in logged["truncate_targets"]]
    projected = [dump.get("train/projected_share") for dump in logged["project_weights"]]
    assert all(v is not None and 0.0 <= v <= 1.0 for v in truncated + projected), (truncated, projected)
    assert max(truncated) > 0.0 and max(projected) > 0.0
    assert all("train/projected_share" not in dump for dump in logged["truncate_targets"])
    assert all("train/truncated_share" not in dump for dump in logged["project_weights"])


@pytest.mark.parametrize("algo", [ER, ERSigma, ResidualER, ResidualERSigma])
def test_the_replay_ratio_bounds_updates_per_new_sample(algo):
    """With replay_ratio r, the replayed updates stay within r x the transitions stored plus one trajectory's worth
    per phase; without it, the thesis's 100 trajectories per phase make far more."""
    model = algo("TileQ", "CartPole-v1", seed=0, replay_ratio=4.0, value_bound_action="ignore").learn(3000)
    longest = max(model.replay_buffer.trajectory_length[: model.replay_buffer.n_trajectories])
    assert model.replay_updates <= 4.0 * 3000 + longest
    assert model.replay_updates >= 4.0 * 3000 - 4.0 * longest - 4.0 * 500  # the last episode's samples may wait
    literal = algo("TileQ", "CartPole-v1", seed=0, value_bound_action="ignore").learn(3000)
    assert literal.replay_updates > 5 * model.replay_updates


@pytest.mark.parametrize("replay_order", ["reversed", "forward", "uniform", "prioritized"])
def test_every_replay_order_takes_every_stabilizer(replay_order):
    """The stabilizers and the replay ratio with each order ER has: prioritized sweeping replays single transitions,
    so the ratio's budget is its phase's length (at most r x the transitions stored; fewer only where no |delta|
    exceeds the threshold)."""
    model = ER(
        "TileQ",
        "sb3_er/WindyCliff-v0",
        seed=0,
        replay_order=replay_order,
        preset="stable",
        truncate_targets=True,
        target_copy=True,
        step_size_bound=True,
        replay_ratio=4.0,
    ).learn(600)
    longest = max(model.replay_buffer.trajectory_length[: model.replay_buffer.n_trajectories])
    assert 0 < model.replay_updates <= 4.0 * 600 + (0 if replay_order == "prioritized" else longest)
    assert model.values_out_of_range == 0


def test_prioritized_updates_and_a_replay_ratio_are_one_setting_twice():
    with pytest.raises(ValueError, match="prioritized_updates=5 and replay_ratio=3.0 both set"):
        ER("TileQ", "sb3_er/WindyCliff-v0", replay_order="prioritized", prioritized_updates=5, replay_ratio=3.0)


def test_presets_resolve_with_explicit_arguments_winning():
    none = dict.fromkeys(
        (
            "n_replays",
            "replay_ratio",
            "truncate_targets",
            "target_copy",
            "step_size_bound",
            "replays_per_stored_trajectory",
        )
    )
    assert resolve_preset("thesis", none) == PRESETS["thesis"]
    assert resolve_preset("stable", none) == PRESETS["stable"]
    assert resolve_preset("stable", {**none, "truncate_targets": False})["truncate_targets"] is False
    volume = resolve_preset("stable", {**none, "n_replays": 7})  # an explicit volume replaces the preset's
    assert volume["n_replays"] == 7 and volume["replay_ratio"] is None
    # the resolved values name the volume the replay uses, and only that one
    per_stored = resolve_preset("thesis", {**none, "replays_per_stored_trajectory": 10.0})
    assert (per_stored["n_replays"], per_stored["replays_per_stored_trajectory"]) == (None, 10.0)
    ratio = ERSigma("TileQ", "CartPole-v1", replay_ratio=16).stabilizers
    assert (ratio["n_replays"], ratio["replays_per_stored_trajectory"], ratio["replay_ratio"]) == (None, None, 16)
    with pytest.raises(ValueError, match="preset"):
        resolve_preset("fast", none)
    model = ERSigma("TileQ", "CartPole-v1", preset="stable", target_copy=False)
    assert model.stabilizers == {**PRESETS["stable"], "target_copy": False}


@pytest.mark.parametrize(
    "volumes",
    [
        dict(n_replays=1, replay_ratio=2),
        dict(n_replays=3, replays_per_stored_trajectory=2.0),
        dict(replays_per_stored_trajectory=2.0, replay_ratio=4),
    ],
)
@pytest.mark.parametrize("algo", [ER, ERSigma, ResidualER, ResidualERSigma])
def test_two_replay_volumes_at_once_are_refused(algo, volumes):
    """Each of the three forms sets the whole replay volume: two at once would leave one unread."""
    first, second = volumes
    with pytest.raises(ValueError, match=f"give one replay volume, not {first}=.* and {second}="):
        algo("TileQ", "CartPole-v1", **volumes)
    with pytest.raises(ValueError, match="replay_ratio .* must be a finite number > 0.0"):
        algo("TileQ", "CartPole-v1", replay_ratio=0)  # no replay at all: n_replays=0 says that


@pytest.mark.parametrize("algo", [ER, ERSigma, ResidualER, ResidualERSigma])
def test_a_loaded_model_replays_with_the_stabilizers_it_was_saved_with(algo, tmp_path, monkeypatch):
    """A later change to a preset does not change what a saved model does: "stable" once meant truncation with the
    target copy. load's keyword arguments still win, one stabilizer at a time, and a preset given to load resolves
    anew."""
    earlier = {**PRESETS["stable"], "truncate_targets": True, "target_copy": True, "project_weights": False}
    monkeypatch.setitem(PRESETS, "stable", earlier)
    algo("TileQ", "CartPole-v1", preset="stable", seed=0).save(tmp_path / "m")
    monkeypatch.undo()
    assert PRESETS["stable"]["project_weights"] is True
    loaded = algo.load(tmp_path / "m")
    assert loaded.stabilizers == earlier and loaded._target_copy is not None
    assert algo.load(tmp_path / "m", target_copy=False).stabilizers == {**earlier, "target_copy": False}
    assert algo.load(tmp_path / "m", preset="stable").stabilizers == PRESETS["stable"]
    assert algo.load(tmp_path / "m", preset="thesis").stabilizers == PRESETS["thesis"]
    ratio = algo.load(tmp_path / "m", replay_ratio=8).stabilizers
    assert ratio == {**earlier, "n_replays": None, "replay_ratio": 8}
    # a file whose stabilizers predate a later one (no project_weights) replays without it, as it was saved
    old = algo("TileQ", "CartPole-v1", preset="stable", seed=0)
    old.stabilizers = {name: value for name, value in earlier.items() if name != "project_weights"}
    old.save(tmp_path / "old")
    assert algo.load(tmp_path / "old").stabilizers == earlier


def test_a_file_saved_before_the_stabilizers_named_their_volume_replays_by_its_attribute(tmp_path):
    """Files written before the resolved values named the replay volume held n_replays=100 beside an attribute
    replays_per_stored_trajectory that the replay read: they keep replaying per stored trajectory."""
    model = ERSigma("TileQ", "CartPole-v1", replays_per_stored_trajectory=0.5, seed=0).learn(300)
    model.stabilizers = {
        name: value for name, value in PRESETS["thesis"].items() if name != "replays_per_stored_trajectory"
    }
    model.save(tmp_path / "old")
    loaded = ERSigma.load(tmp_path / "old", env="CartPole-v1")
    assert loaded.stabilizers == {**PRESETS["thesis"], "n_replays": None, "replays_per_stored_trajectory": 0.5}
    loaded.replay_buffer = model.replay_buffer  # SB3 saves the buffer apart
    stored = loaded.replay_buffer.n_stored_trajectories
    assert stored > 2 and loaded._replays_per_phase() == round(0.5 * stored)


def test_a_volume_given_to_load_replaces_the_saved_one_with_or_without_a_preset(tmp_path):
    ERSigma("TileQ", "CartPole-v1", preset="stable", n_replays=3).save(tmp_path / "a")
    loaded = ERSigma.load(tmp_path / "a", preset="thesis", replay_ratio=2.0)
    assert loaded.stabilizers == {**PRESETS["thesis"], "n_replays": None, "replay_ratio": 2.0}
    assert loaded.n_replays is None  # the file it saves next names one volume
    loaded.save(tmp_path / "b")
    assert ERSigma.load(tmp_path / "b", preset="stable").stabilizers == {
        **PRESETS["stable"],
        "n_replays": None,
        "replay_ratio": 2.0,
    }


@pytest.mark.parametrize(
    "crafted, field",
    [
        ({"n_replays": -5}, "n_replays"),
        ({"n_replays": None, "replay_ratio": 0.0}, "replay_ratio"),
        ({"n_replays": 2.5}, "n_replays"),
        ({"target_copy": "no"}, "target_copy"),
        ({"bogus": 1}, "expected the entries"),
        ({"n_replays": None}, "expected one replay volume"),
    ],
)
def test_a_files_stabilizers_are_checked_when_read_back(crafted, field, tmp_path):
    model = ERSigma("TileQ", "CartPole-v1", seed=0)
    model.stabilizers = {**model.stabilizers, **crafted}
    model.save(tmp_path / "m")
    with pytest.raises(ValueError, match=rf"m.zip: .*stabilizers.*{field}"):
        ERSigma.load(tmp_path / "m")


def test_a_model_saved_before_presets_loads_with_the_thesis_algorithm(tmp_path):
    """A file without the preset's attributes (saved before they existed) loads as the thesis's algorithm."""
    model = ERSigma("TileQ", "CartPole-v1", preset="stable", seed=0)
    model.save(tmp_path / "m")
    loaded = ERSigma.load(tmp_path / "m")
    assert loaded.stabilizers == model.stabilizers  # the file's values
    for name in (
        "preset",
        "truncate_targets",
        "target_copy",
        "step_size_bound",
        "averager",
        "replay_ratio",
        "stabilizers",
    ):
        del model.__dict__[name]
    model.save(tmp_path / "old")
    old = ERSigma.load(tmp_path / "old")
    assert old.preset == "thesis" and old.stabilizers == PRESETS["thesis"]

    class StableByDefault(ERSigma):  # a later version whose default preset is "stable"
        def __init__(self, *args, preset="stable", **kwargs):
            super().__init__(*args, preset=preset, **kwargs)

    assert StableByDefault("TileQ", "CartPole-v1", _init_setup_model=False).preset == "stable"
    old = StableByDefault.load(tmp_path / "old")
    assert old.preset == "thesis" and old.stabilizers == PRESETS["thesis"]
    assert StableByDefault.load(tmp_path / "m").stabilizers == loaded.stabilizers
