"""Replay, Sarsa(lambda) and learn() throughput, and the value watch's cost; prints the figures recorded in the docs.

    python benchmarks/replay_throughput.py [--quick] [--baseline CHECKOUT]

(a) the walker setup: 4-D state, 15 actions, 16 tilings; (b) the LEO setup: 10-D state, 343 actions (voltages tiled),
16 tilings. Each ER variant replays a buffer of random-action trajectories recorded in the real env (sb3_er_envs; LEO
needs the dmc extra) with one kernel call per phase; the reference is a plain-NumPy implementation of the same update
called once per update. Rates are per second of this process's CPU time (single-threaded), so other load on
the machine does not count against them. "watch cost" is the kernel's time per update with the value watch (every
target and Q(s, a) folded into the watch array, ER-sigma's target shift too) over its time without it, in one run:
the median of alternating timed calls with and without. The weights are allocated and touched once, before any
timing, so that the operating system's first-touch page faults are not counted as kernel work.

On a shared or virtual machine the rate of one process moves by up to 2x between runs, which hides any change
smaller than that. ``--baseline CHECKOUT`` (another checkout of this repository, or its ``sb3_er/common/kernels.py``)
loads that version's kernels into the same process and alternates its replay phases with the current ones on the
same buffer; the ``vs baseline`` column is the median of the per-round rate ratios, current over baseline, which
the machine's drift affects far less. Use it to check that a change keeps the replay kernels' speed.
"""

import argparse
import importlib.util
import shutil
import sys
import tempfile
import time
from pathlib import Path

import gymnasium as gym
import numba as nb
import numpy as np

from sb3_er import SarsaLambda
from sb3_er.common import kernels
from sb3_er.common.buffers import TrajectoryReplayBuffer
from sb3_er.common.tile_coding import TileCoder

SETUPS = {
    "(a) walker: 4-D, 15 actions": dict(env_id="sb3_er/SimplestWalker-v0", transitions=20_000, memory_size=2**22),
    "(b) LEO: 10-D, 343 actions": dict(env_id="sb3_er/Leo-v0", transitions=5_000, memory_size=2**24),
}
VARIANTS = {
    "ER": (kernels.SIGMA_NONE, 0.0),
    "ER-sigma": (kernels.SIGMA_AVERAGE_WORST, 0.0),
    "residual ER": (kernels.SIGMA_NONE, 1.0),
    "residual ER-sigma": (kernels.SIGMA_AVERAGE_WORST, 1.0),
}
GAMMA, ALPHA, EPSILON = 0.99, 0.2, 0.05


def env_coder(env: gym.Env, memory_size: int) -> TileCoder:
    """The env's own tile coding (thesis Tables 4.2 and 4.3; LEO tiles its voltages too), 16 tilings."""
    env = env.unwrapped
    nvec = [env.action_space.n] if hasattr(env.action_space, "n") else list(env.action_space.nvec)
    return TileCoder(
        env.tile_widths,
        nvec,
        n_tilings=16,
        memory_size=memory_size,
        action_values=getattr(env, "action_values", None),
        action_tile_widths=getattr(env, "action_tile_widths", None),
    )


def recorded_buffer(env: gym.Env, coder: TileCoder, n_transitions: int) -> TrajectoryReplayBuffer:
    """Trajectories of random actions in the real env (falls and time limits end them, footsteps split them)."""
    buffer = TrajectoryReplayBuffer(n_transitions, coder)
    obs, _ = env.reset(seed=0)
    env.action_space.seed(0)
    flat_index = np.arange(coder.n_actions).reshape(coder.action_nvec)
    for _ in range(n_transitions - 1):
        action = env.action_space.sample()
        next_obs, reward, terminated, truncated, info = env.step(action)
        buffer.add(obs, coder.slots(obs), int(flat_index[tuple(np.atleast_1d(action))]), reward, next_obs)
        if terminated or truncated or info.get("segment_end", False):
            buffer.close_trajectory(next_obs, terminated)
        obs = env.reset()[0] if terminated or truncated else next_obs
    buffer.close_trajectory(obs, False)
    return buffer


def _alternate(rate, size, watch, rounds) -> tuple[float, float]:
    """(median rate without the watch, median ratio of the time per unit with it to without it) over ``rounds``
    alternating calls ``rate(size, watch_array)``, after one small call of each to compile."""
    rate(1, kernels.NO_WATCH)
    rate(1, watch)
    without, ratios = [], []
    for _ in range(rounds):
        off = rate(size, kernels.NO_WATCH)
        on = rate(size, watch)
        without.append(off)
        ratios.append(off / on)
    return float(np.median(without)), float(np.median(ratios))


def load_kernels(checkout: str):
    """The kernels of another checkout, loaded beside the current ones under their own module name, from a copy in a
    temporary folder (numba caches kernels next to their files, under the module's name): a checkout's
    ``sb3_er/common/kernels.py`` (the single module of earlier versions, which took positional arguments) as the
    module ``baseline_kernels``, or its ``sb3_er/common/kernels/`` package (argument bundles) as the package
    ``baseline_kernels`` with its imports pointed at itself.

    :param checkout: a checkout of this repository, or its kernels module or package folder.
    """
    path = Path(checkout)
    if path.is_dir() and (path / "__init__.py").is_file() and (path / "bundles.py").is_file():
        package = path
    elif path.is_dir() and (path / "sb3_er" / "common" / "kernels" / "__init__.py").is_file():
        package = path / "sb3_er" / "common" / "kernels"
    else:
        package = None
        if path.is_dir():
            path = path / "sb3_er" / "common" / "kernels.py"
        if not path.is_file():
            raise SystemExit(
                f"--baseline: {path} does not exist; give a checkout of this repository (a folder holding "
                "sb3_er/common/kernels.py or sb3_er/common/kernels/), or that file or folder"
            )
    if package is not None:
        folder = Path(tempfile.mkdtemp(prefix="baseline_kernels_"))
        (folder / "baseline_kernels").mkdir()
        for source in package.glob("*.py"):
            text = source.read_text(encoding="utf-8").replace("sb3_er.common.kernels", "baseline_kernels")
            (folder / "baseline_kernels" / source.name).write_text(text, encoding="utf-8")
        sys.path.insert(0, str(folder))
        return importlib.import_module("baseline_kernels")
    # a copy, never the checkout's own file: numba caches a kernel next to its source under the module's name, and a
    # "baseline_kernels" entry in the checkout's __pycache__ would break that checkout's own imports of its kernels
    folder = Path(tempfile.mkdtemp(prefix="baseline_kernels_"))
    shutil.copyfile(path, folder / "baseline_kernels.py")
    sys.path.insert(0, str(folder))
    return importlib.import_module("baseline_kernels")


def bundled(module) -> bool:
    """Whether ``module``'s kernels take argument bundles (else the positional arguments of earlier versions)."""
    return hasattr(module, "Weights")


class ReplayTimer:
    """Times one replay phase of ``n`` trajectories from all-zero weights, in CPU seconds, with a given kernels module
    (the current one, or a baseline's: each called in its own convention; a version without the value watch gets no
    watch argument)."""

    def __init__(self, coder, buffer, sigma, zeta):
        self.coder, self.buffer, self.sigma, self.zeta = coder, buffer, sigma, zeta
        self.theta = np.ones(coder.n_weights)  # touched once, so that no timed phase pays first-touch page faults
        self.q_scratch, self.w_scratch = np.zeros(coder.n_actions), np.zeros(coder.n_actions)

    def _bundled_call(self, module, n, watch_array):
        """A version that takes bundles: each built by that version's own constructors (its fields may differ)."""
        coder, buffer = self.coder, self.buffer
        make = module.make
        data = buffer.replay_data()
        rule = dict(
            target_kind=module.TARGET_SARSA,
            sigma_kind=self.sigma,
            residual_zeta=self.zeta,
            residual_next_action=False,
            step_size=ALPHA / coder.n_tilings,
            gamma=GAMMA,
            epsilon=EPSILON,
        )
        replay = dict(n_trajectories=n, order=module.ORDER_REVERSED, picks_rng=module.new_rng_state(1, 1))
        if "truncate" in module.UpdateRule._fields:
            rule.update(
                truncate=False, value_low=-np.inf, value_high=np.inf, step_bound=False, step_cap=np.full(1, np.inf)
            )
            replay.update(max_updates=-1)
        if "averager" in module.UpdateRule._fields:
            rule.update(averager=False)
        if "project" in module.UpdateRule._fields:
            rule.update(project=False)
        if hasattr(module, "weights_bundle"):
            weights = module.weights_bundle(self.theta, 0.0, 0.0, 0)
        else:
            weights = make(module.Weights, theta=self.theta, initial_low=0.0, initial_span=0.0, initial_seed=0)
        return module.replay_phase(
            weights,
            module.Trajectories(*data),
            module.TileLayout(*coder.layout),
            make(module.UpdateRule, **rule),
            make(module.Replay, **replay),
            module.new_rng_state(1, 0),
            module.Scratch(self.q_scratch, self.w_scratch),
            watch_array if module is kernels else module.NO_WATCH,
        )

    def _positional_call(self, module, n):
        """Earlier versions' replay_phase: the buffer's arrays and counters, the coder, then the update's settings."""
        coder, data = self.coder, self.buffer.replay_data()
        arguments = [
            self.theta,
            data.visits,
            data.slots,
            data.actions,
            data.rewards,
            data.transition_trajectory,
            data.trajectory_start,
            data.trajectory_length,
            data.trajectory_terminated,
            data.trajectory_next_slots,
            data.oldest_trajectory,
            data.n_closed_trajectories,
            data.first_row,
            data.n_transitions,
            data.open_trajectory,
            data.open_length,
            data.open_next_slots,
            coder.stride,
            coder.action_columns,
            coder.columns_are_actions,
            n,
            module.ORDER_REVERSED,
            module.TARGET_SARSA,
            self.sigma,
            self.zeta,
            False,
            ALPHA / coder.n_tilings,
            GAMMA,
            EPSILON,
            module.new_rng_state(1, 1),
            module.new_rng_state(1, 0),
            self.q_scratch,
            self.w_scratch,
            *getattr(module, "ZERO_INITIAL", ()),
        ]
        if hasattr(module, "NO_WATCH"):
            arguments.append(module.NO_WATCH)
        return module.replay_phase(*arguments)

    def rate(self, module, n, watch_array) -> float:
        """Updates per CPU second of one phase of ``n`` replays with ``module``'s kernels.

        :param module: a kernels module (the current one or a baseline's).
        :param n: trajectories to replay.
        :param watch_array: the value watch (the current kernels only).
        """
        self.theta.fill(0.0)
        start = time.process_time()
        if bundled(module):
            updates = self._bundled_call(module, n, watch_array)[0]
        else:
            updates = self._positional_call(module, n)[0]
        return updates / (time.process_time() - start)


def kernel_updates_per_second(coder, buffer, sigma, zeta, n_replays, rounds=5) -> tuple[float, float]:
    """(updates per CPU second without the value watch, time per update with it over time without it): the median
    of ``rounds`` alternating pairs of phases from the same weights and generators."""
    timer = ReplayTimer(coder, buffer, sigma, zeta)
    return _alternate(lambda n, watch: timer.rate(kernels, n, watch), n_replays, kernels.new_watch(-1e6, 1e6), rounds)


def against_baseline(baseline, coder, buffer, sigma, zeta, n_replays, rounds=9) -> tuple[float, float]:
    """(the baseline's median updates per CPU second, median of the per-round ratios current / baseline), both
    without the value watch, alternating phases of the two versions on the same buffer."""
    timer = ReplayTimer(coder, buffer, sigma, zeta)
    for module in (kernels, baseline):
        timer.rate(module, 1, kernels.NO_WATCH)
    rates, ratios = [], []
    for _ in range(rounds):
        current = timer.rate(kernels, n_replays, kernels.NO_WATCH)
        before = timer.rate(baseline, n_replays, kernels.NO_WATCH)
        rates.append(before)
        ratios.append(current / before)
    return float(np.median(rates)), float(np.median(ratios))


def numpy_updates_per_second(coder, buffer, sigma_on, zeta, n_updates) -> float:
    """The same reversed-trajectory update in plain NumPy, one call per update."""
    theta = np.zeros(coder.n_weights)
    rng = np.random.default_rng(1)
    columns, stride, n = coder.action_columns, coder.stride, coder.n_tilings
    tilings = np.arange(n)

    def update(p, next_slots, terminal):
        a = buffer.actions[p]
        active = buffer.slots[p] * stride + columns[:, a]
        target = buffer.rewards[p]
        if not terminal:
            rows = next_slots[:, None] * stride + columns
            q = theta[rows].sum(axis=0)
            if sigma_on:
                w = buffer.visits[rows].sum(axis=0).astype(float)
                visited = w > 0
                if visited.any():
                    sigma = 0.5 * (q.sum() / w.sum() + np.min(q[visited] / w[visited]))
                    q = q + (n - w) * sigma
            a_next = rng.integers(len(q)) if rng.random() < EPSILON else int(np.argmax(q))
            target += GAMMA * q[a_next]
        delta = target - theta[active].sum()
        np.add.at(theta, active, ALPHA / n * delta)
        if zeta and not terminal:
            np.add.at(theta, next_slots[tilings] * stride + columns[:, a], -ALPHA / n * delta * zeta * GAMMA)

    start = time.process_time()
    done = 0
    while done < n_updates:
        j = (buffer.oldest_trajectory + rng.integers(buffer.n_trajectories)) % buffer.capacity
        first, length = buffer.trajectory_start[j], buffer.trajectory_length[j]
        for t in range(length - 1, -1, -1):
            p = (first + t) % buffer.capacity
            last = t == length - 1
            next_slots = buffer.trajectory_next_slots[j] if last else buffer.slots[(p + 1) % buffer.capacity]
            update(p, next_slots, last and buffer.trajectory_terminated[j])
            done += 1
    return done / (time.process_time() - start)


@nb.njit
def _sarsa_lambda_episode(weights, trace, layout, rule, states, n_steps, rng, scratch, watch):
    """``n_steps`` Sarsa(lambda) steps along ``states`` (reward -1, never terminal) through the per-step kernels."""
    n_tilings = layout[1].shape[0]
    slots = np.zeros(n_tilings, np.int64)
    next_slots = np.zeros(n_tilings, np.int64)
    action = kernels.select_action(weights[0], states[0], layout, EPSILON, rng, slots, scratch[0])
    for k in range(n_steps):
        transition = (slots, action, -1.0, False, states[k + 1], next_slots)
        action, _, _ = kernels.sarsa_lambda_step(weights, trace, layout, rule, transition, rng, scratch, watch)
        slots, next_slots = next_slots, slots


def sarsa_lambda_steps_per_second(coder, n_steps, rounds=5) -> tuple[float, float]:
    """(steps per CPU second without the value watch, time per step with it over time without it), medians of
    alternating runs."""
    rng = np.random.default_rng(0)
    states = np.cumsum(rng.normal(0.0, 1.0 / 3.0, (n_steps + 1, coder.n_dims)) * coder.tile_widths, axis=0)
    capacity = coder.n_tilings * 120
    make = kernels.make
    rule = kernels.update_rule(ALPHA / coder.n_tilings, GAMMA, EPSILON)
    scratch = (np.zeros(coder.n_actions), np.zeros(coder.n_actions))

    def run(steps, watch):
        weights = kernels.weights_bundle(np.zeros(coder.n_weights), 0.0, 0.0, 0)
        trace = make(
            kernels.Trace,
            index=np.zeros(capacity, np.int64),
            value=np.zeros(capacity),
            position=np.full(coder.n_weights, -1, np.int32),
            length=np.zeros(1, np.int64),
            decay=GAMMA * 0.92,
            cutoff=0.01,
        )
        start = time.process_time()
        _sarsa_lambda_episode(
            tuple(weights),
            tuple(trace),
            tuple(coder.layout),
            tuple(rule),
            states,
            steps,
            kernels.new_rng_state(0),
            scratch,
            watch,
        )
        return steps / (time.process_time() - start)

    return _alternate(run, n_steps, kernels.new_watch(-1e6, 1e6), rounds)


def call_overhead_us(coder, calls=20_000) -> dict[str, float]:
    """Microseconds per call of ``kernels.select_action`` from Python with its layout as a plain tuple (what the
    learn loop passes) and as the named TileLayout (what the phase kernels take): the cost of numba typing a named
    tuple's fields in Python at every call, which is why the per-step kernels take plain tuples."""
    obs = np.zeros(coder.n_dims)
    slots, q = np.zeros(coder.n_tilings, np.int64), np.zeros(coder.n_actions)
    theta, rng = np.zeros(coder.n_weights), kernels.new_rng_state(0)
    figures = {}
    for name, layout in (("plain tuple", tuple(coder.layout)), ("named tuple", coder.layout)):
        kernels.select_action(theta, obs, layout, EPSILON, rng, slots, q)
        start = time.perf_counter()
        for _ in range(calls):
            kernels.select_action(theta, obs, layout, EPSILON, rng, slots, q)
        figures[name] = (time.perf_counter() - start) / calls * 1e6
    return figures


def learn_steps_per_second(env_id, policy_kwargs, n_steps) -> float:
    model = SarsaLambda(
        "TileQ",
        gym.make(env_id),
        gamma=1.0,
        exploration_rate=0.0,
        trace_lambda=0.9,
        policy_kwargs=policy_kwargs,
        value_bound_action="ignore",  # a speed run: MountainCar's values overshoot 0 under these settings
        seed=0,
    )
    model.learn(2000)
    start = time.process_time()
    model.learn(n_steps)
    return n_steps / (time.process_time() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="smaller runs, for a smoke test")
    parser.add_argument(
        "--baseline",
        metavar="CHECKOUT",
        help="another checkout (or its sb3_er/common/kernels.py or kernels/ package) to time in the same process",
    )
    args = parser.parse_args()
    scale = 0.1 if args.quick else 1.0
    baseline = load_kernels(args.baseline) if args.baseline else None

    import sb3_er_envs  # noqa: F401  (registers the env ids)

    header = (
        f"{'setup':32s} {'variant':18s} {'kernel upd/s':>14s} {'numpy upd/s':>12s} {'speed-up':>9s} {'watch cost':>10s}"
    )
    print(header + (f" {'baseline upd/s':>15s} {'vs baseline':>11s}" if baseline else ""))
    for name, setup in SETUPS.items():
        env = gym.make(setup["env_id"])
        coder = env_coder(env, setup["memory_size"])
        buffer = recorded_buffer(env, coder, int(setup["transitions"] * max(scale, 0.2)))
        n_replays = max(20, int(1000 * scale))
        for variant, (sigma, zeta) in VARIANTS.items():
            fast, cost = kernel_updates_per_second(coder, buffer, sigma, zeta, n_replays)
            slow = numpy_updates_per_second(coder, buffer, sigma != kernels.SIGMA_NONE, zeta, int(3000 * scale) + 100)
            line = f"{name:32s} {variant:18s} {fast:14,.0f} {slow:12,.0f} {fast / slow:8.0f}x {cost - 1:+10.1%}"
            if baseline:
                before, ratio = against_baseline(baseline, coder, buffer, sigma, zeta, n_replays)
                line += f" {before:15,.0f} {ratio:10.2f}x"
            print(line, flush=True)

    walker = TileCoder([0.1, 0.1, 0.11, 0.21], [15], n_tilings=16)
    rate, cost = sarsa_lambda_steps_per_second(walker, int(1_000_000 * scale))
    print(f"\nSarsa(lambda) kernel, walker setup: {rate:,.0f} steps/s; watch cost {cost - 1:+.1%}")
    overhead = call_overhead_us(walker, int(20_000 * max(scale, 0.2)))
    print(
        "select_action called from Python: " + ", ".join(f"{us:.2f} us with a {kind}" for kind, us in overhead.items())
    )
    for env_id, policy_kwargs in (
        ("MountainCar-v0", dict(n_tilings=8, tiles_per_dimension=8)),
        ("CartPole-v1", dict(n_tilings=8, tile_widths=[0.5, 0.5, 0.05, 0.5])),
    ):
        rate = learn_steps_per_second(env_id, policy_kwargs, int(100_000 * scale))
        print(f"SarsaLambda.learn end to end on {env_id}: {rate:,.0f} steps/s")


if __name__ == "__main__":
    main()
