"""Control steps per second of ``sb3_er/Leo-v0`` and where a control step goes, in CPU time.

Usage: ``python benchmarks/leo_speed.py [--episodes N] [--repeats R] [--seed S] [--learn-steps N]``

Every figure is CPU time of this process (``time.process_time``), so other jobs on the machine do not count against
it, and each rate is the best of ``--repeats`` runs (the median in brackets): on a loaded machine CPU time still
varies by 5-10 % between runs (shared caches, hyper-threads). Printed:

* control steps/s of Erik's hand-made gait (full 25 s episodes) and of uniformly random voltage levels (episodes end
  at falls), both through ``gymnasium.make`` with the policy's own time included;
* control steps/s of the bare physics: the gait's recorded motor commands replayed through
  ``Physics.step_control`` (30 MuJoCo substeps, nothing else), which reproduces the gait's trajectory exactly;
* the profile of a gait control step: the MuJoCo substeps (the replay above) and the Python side in the loop (the
  same gait episodes with the physics step stubbed out), measured in turns with the full gait so that all three see
  the same machine load; the Python side split further by timing each part alone at a mid-gait state; what is left
  is the cost of MuJoCo and Python evicting each other's caches, plus timing spread. MuJoCo's own split of a
  substep comes from its timers (wall clock, so only their ratios are used);
* for information, ``SarsaLambda.learn`` on Leo-v0 with the LEO zoo settings (16 tilings of the 10 state dims and the
  3 voltages): steps/s and the share of ``LeoEnv.step`` in it (``--learn-steps 0`` skips it).
"""

from __future__ import annotations

import argparse
import statistics
import time

import gymnasium as gym
import mujoco
import numpy as np

import sb3_er_envs  # noqa: F401  (registers sb3_er/Leo-v0)
from sb3_er_envs.leo import ObservingGait
from sb3_er_envs.leo.gym_env import _voltages_of_levels
from sb3_er_envs.leo.leo import PHYSICS_SUBSTEPS


def run_episodes(env, episodes: int, seed: int, policy_name: str) -> int:
    """Control steps of ``episodes`` episodes under Erik's gait or uniformly random levels."""
    rng = np.random.default_rng(seed)
    gait = ObservingGait()
    steps = 0
    for episode in range(episodes):
        observation, info = env.reset(seed=seed + episode)
        gait.reset()
        done = False
        while not done:
            action = gait.action(observation, info) if policy_name == "gait" else rng.integers(0, 7, size=3)
            observation, _, terminated, truncated, info = env.step(action)
            steps += 1
            done = terminated or truncated
    return steps


def best_rate(work, repeats: int) -> tuple[float, float]:
    """Best and median of ``count / CPU seconds`` over ``repeats`` calls of ``work() -> count``."""
    rates = []
    for _ in range(repeats):
        start = time.process_time()
        count = work()
        rates.append(count / (time.process_time() - start))
    return max(rates), statistics.median(rates)


def cost_us(function, calls: int, repeats: int) -> float:
    """Least CPU time of one call of ``function()`` [us] over ``repeats`` loops of ``calls`` calls."""
    best = float("inf")
    for _ in range(repeats):
        start = time.process_time()
        for _ in range(calls):
            function()
        best = min(best, (time.process_time() - start) / calls)
    return best * 1e6


def record_gait(env, seed: int) -> list[np.ndarray]:
    """The motor controls of every step of one gait episode (to replay the same trajectory without the task)."""
    leo = env.unwrapped
    gait = ObservingGait()
    observation, info = env.reset(seed=seed)
    gait.reset()
    controls, done = [], False
    while not done:
        observation, _, terminated, truncated, info = env.step(gait.action(observation, info))
        controls.append(leo.physics.data.ctrl.copy())
        done = terminated or truncated
    return controls


def replay_physics(env, controls: list[np.ndarray], seed: int) -> int:
    """Replay recorded controls through the bare 30-substep physics step; returns the control steps."""
    env.reset(seed=seed)
    physics = env.unwrapped.physics
    ctrl = physics.data.ctrl
    for control in controls:
        ctrl[:] = control
        physics.step_control(PHYSICS_SUBSTEPS)
    return len(controls)


def mujoco_split(env, controls: list[np.ndarray], seed: int, repeats: int) -> dict[str, float]:
    """Shares of a MuJoCo substep by stage from MuJoCo's own timers. They are wall clock, so the replay with the least
    total of ``repeats`` is used (preemption only adds) and only its ratios."""
    physics = env.unwrapped.physics
    timer = physics.data.ptr.timer
    T = mujoco.mjtTimer
    parts = {
        "kinematics (positions, com, cameras)": T.mjTIMER_POS_KINEMATICS,
        "inertia (CRB, factorisation)": T.mjTIMER_POS_INERTIA,
        "collision (broad + narrow phase)": T.mjTIMER_POS_COLLISION,
        "constraint building (limits, friction loss, contacts)": T.mjTIMER_POS_MAKE,
        "velocity stage (com velocities, passive, bias)": T.mjTIMER_VELOCITY,
        "actuation": T.mjTIMER_ACTUATION,
        "constraint solver (Newton)": T.mjTIMER_CONSTRAINT,
        "integrator (implicitfast)": T.mjTIMER_ADVANCE,
        "whole substep": T.mjTIMER_STEP,
    }
    best = {"whole substep": float("inf")}
    physics.keep_mujoco_timers = True
    try:
        for _ in range(repeats):
            env.reset(seed=seed)
            for index in range(len(timer)):
                timer[index].duration = 0.0
            replay_physics(env, controls, seed)
            if timer[T.mjTIMER_STEP].duration < best["whole substep"]:
                best = {name: timer[index].duration for name, index in parts.items()}
    finally:
        physics.keep_mujoco_timers = False
    total = best.pop("whole substep")
    shares = {name: duration / total for name, duration in best.items()}
    shares["other (step bookkeeping, checks, sensors, timers)"] = 1.0 - sum(shares.values())
    return shares


def python_side(env, episodes: int, seed: int) -> int:
    """The gait episodes with ``Physics.step_control`` stubbed out: the Python work of a control step in the loop."""
    physics = env.unwrapped.physics
    physics.step_control = lambda nstep: None
    try:
        return run_episodes(env, episodes, seed, "gait")
    finally:
        del physics.step_control


def measure_in_turns(env, controls: list[np.ndarray], episodes: int, seed: int, repeats: int) -> dict[str, list]:
    """Control steps/s of the full gait, the bare physics replay and the Python side, measured in turns."""
    work = {
        "gait": lambda: run_episodes(env, episodes, seed, "gait"),
        "physics": lambda: replay_physics(env, controls, seed),
        "python": lambda: python_side(env, episodes, seed),
    }
    rates = {name: [] for name in work}
    for _ in range(repeats):
        for name, function in work.items():
            rates[name].append(best_rate(function, 1)[0])
    return rates


def python_parts(env, controls: list[np.ndarray], seed: int, repeats: int) -> dict[str, float]:
    """CPU microseconds per call of each Python part of a gait control step, each timed alone at a mid-gait state."""
    leo = env.unwrapped
    physics, task = leo.physics, leo.task
    gait = ObservingGait()
    observation, info = env.reset(seed=seed)
    gait.reset()
    for _ in range(len(controls) // 2):
        observation, _, _, _, info = env.step(gait.action(observation, info))
    action = gait.action(observation, info)
    voltages = _voltages_of_levels(action)
    state = physics.get_state()
    calls = 20000
    costs = {
        "gait policy (ObservingGait.action)": cost_us(lambda: gait.action(observation, info), calls, repeats),
        "action check + levels to volts": cost_us(lambda: _voltages_of_levels(action), calls, repeats),
        "task before_step (controllers, clip, ctrl)": cost_us(
            lambda: task.apply_voltages(*voltages, physics), calls, repeats
        ),
        "task after_step (all of it)": cost_us(lambda: task.after_step(physics), calls, repeats),
    }
    raw = list(task._raw_rates)
    costs["  of which: rate filter"] = cost_us(lambda: task._update_rates(raw), calls, repeats)
    costs["  of which: motor energy"] = cost_us(task._motor_energy, calls, repeats)
    costs["  of which: foot contacts"] = cost_us(physics.foot_contacts, calls, repeats)
    costs["observation (stance mapping, clip)"] = cost_us(leo._observation, calls, repeats)
    costs["info dict"] = cost_us(lambda: task.info(physics), calls, repeats)
    # The wrappers gym.make adds (OrderEnforcing, PassiveEnvChecker): LeoEnv.step replaced by a stub.
    result = (leo._observation(), 0.0, False, False, task.info(physics))
    leo.step = lambda _action: result
    try:
        costs["Gymnasium wrappers (gym.make)"] = cost_us(lambda: env.step(action), calls, repeats)
    finally:
        del leo.step
    physics.set_state(state)
    return costs


def learner_share(steps: int, seed: int) -> tuple[float, float, float]:
    """``SarsaLambda.learn`` on Leo-v0 with the zoo settings: steps/s, and LeoEnv.step's CPU share and us/step."""
    from sb3_er import SarsaLambda
    from sb3_er.zoo import model_kwargs

    env = gym.make("sb3_er/Leo-v0")
    leo = env.unwrapped
    model = SarsaLambda(env=env, seed=seed, **model_kwargs("sarsa_lambda", "sb3_er/Leo-v0"))
    model.learn(1000)  # compiles the numba kernels
    spent = [0.0, 0]
    step = leo.step

    def timed_step(action):
        start = time.process_time()
        result = step(action)
        spent[0] += time.process_time() - start
        spent[1] += 1
        return result

    leo.step = timed_step
    start = time.process_time()
    model.learn(steps, reset_num_timesteps=False)
    total = time.process_time() - start
    env.close()
    return steps / total, spent[0] / total, spent[0] / max(spent[1], 1) * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=4, help="gait episodes per repeat (default 4)")
    parser.add_argument("--repeats", type=int, default=3, help="repeats of each measurement (default 3)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--learn-steps",
        type=int,
        default=10000,
        help="SarsaLambda.learn steps for the learner's share (default 10000; 0 skips it)",
    )
    args = parser.parse_args()
    if args.episodes < 1 or args.repeats < 1:
        parser.error("--episodes and --repeats must be at least 1")
    env = gym.make("sb3_er/Leo-v0")
    run_episodes(env, 1, args.seed, "gait")  # warm-up
    print(
        f"sb3_er/Leo-v0, {PHYSICS_SUBSTEPS} physics substeps per 1/30 s control step; CPU time, best of "
        f"{args.repeats} (median)"
    )
    gait_rate, gait_median = best_rate(lambda: run_episodes(env, args.episodes, args.seed, "gait"), args.repeats)
    print(
        f"Erik's gait (gym.make, policy included): {gait_rate:6.0f} control steps/s ({gait_median:.0f}); "
        f"a 25 s episode in {750 / gait_rate:.3f} s"
    )
    random_rate, random_median = best_rate(
        lambda: run_episodes(env, 10 * args.episodes, args.seed, "random"), args.repeats
    )
    print(f"random levels (gym.make, falls end episodes): {random_rate:6.0f} control steps/s ({random_median:.0f})")
    controls = record_gait(env, args.seed)
    physics_rate, physics_median = best_rate(lambda: replay_physics(env, controls, args.seed), args.repeats)
    print(
        f"bare physics (the gait's controls replayed, {PHYSICS_SUBSTEPS} substeps): {physics_rate:6.0f} control "
        f"steps/s ({physics_median:.0f})"
    )

    rates = measure_in_turns(env, controls, args.episodes, args.seed, args.repeats)
    step_us, physics_us, python_us = (1e6 / max(rates[name]) for name in ("gait", "physics", "python"))
    print(f"\nprofile of a gait control step, CPU us (best of {args.repeats}, measured in turns), share of the step")
    print(f"  {'whole control step (Erik gait, gym.make)':56s} {step_us:7.2f} us 100.0 %")
    print(
        f"  {'MuJoCo substeps (30 x mj_step, Physics.step_control)':56s} {physics_us:7.2f} us "
        f"{100 * physics_us / step_us:5.1f} %"
    )
    print(
        f"  {'Python side in the loop (physics stubbed out)':56s} {python_us:7.2f} us "
        f"{100 * python_us / step_us:5.1f} %"
    )
    for name, us in python_parts(env, controls, args.seed, args.repeats).items():
        print(f"    {name:54s} {us:7.2f} us {100 * us / step_us:5.1f} %")
    rest = step_us - physics_us - python_us
    print(
        f"  {'rest (MuJoCo and Python evicting each other, spread)':56s} {rest:7.2f} us {100 * rest / step_us:5.1f} %"
    )
    print("MuJoCo's split of a substep (its wall-clock timers):")
    for name, share in mujoco_split(env, controls, args.seed, args.repeats).items():
        print(f"  {name:56s} {100 * share:5.1f} %")
    env.close()

    if args.learn_steps > 0:
        rate, share, env_us = learner_share(args.learn_steps, args.seed)
        print(
            f"\nSarsaLambda.learn on Leo-v0 (zoo settings, {args.learn_steps} steps): {rate:.0f} steps/s; "
            f"LeoEnv.step {env_us:.0f} us/step = {100 * share:.0f} %, learner and SB3 loop "
            f"{(1 / rate - share / rate) * 1e6:.0f} us/step = {100 * (1 - share):.0f} %"
        )


if __name__ == "__main__":
    main()
