"""Observation ranges of dm_control's swing-up tasks, measured from rollouts (the ranges sb3-er's tilings split).

    python benchmarks/dmc_ranges.py [--episodes 10] > results/measured/dmc_tilings/ranges.txt

The suite declares every observation unbounded, so the tile widths of ``sb3_er/data/tilings.yml`` are fractions of
ranges measured here. Each task runs ``--episodes`` whole episodes (1,000 steps) under each of three behaviours over
the 7 torque levels a model uses by default (-1 to 1): ``random`` draws a level every step (what an untrained
epsilon-greedy learner does), ``held`` keeps a random level for 10-200 steps (slow, wide swings), ``pump`` pushes
with the actuated joint's velocity (full torque in its direction; the cart-pole's cart against the pole's
angular velocity times cos(angle): pumps energy in, the fastest the system moves under these torques). Printed per
flattened observation dimension (the Dict's keys in FlattenObservation's order): the minimum and maximum over all
rollouts, per behaviour, and the 0.5 and 99.5 percentiles over all of them.
"""

import argparse

import numpy as np

from sb3_er.common.dict_observations import observation_keys, register_dm_control_envs

TASKS = ("dm_control/cartpole-swingup-v0", "dm_control/pendulum-swingup-v0", "dm_control/acrobot-swingup-v0")
#: The flattened index of the velocity ``pump`` pushes with: the hinge's (pendulum), the elbow's (acrobot: only the
#: elbow is actuated); the cart-pole pushes the cart against the pole's angular velocity times cos(angle).
ACTUATED_VELOCITY = {TASKS[1]: 2, TASKS[2]: 5}
LEVELS = np.linspace(-1.0, 1.0, 7)


def rollouts(env_id: str, behaviour: str, episodes: int, seed: int) -> np.ndarray:
    """The flattened observations of ``episodes`` episodes of ``behaviour`` on ``env_id``, (steps, dims)."""
    import gymnasium as gym

    env = gym.wrappers.FlattenObservation(gym.make(env_id))
    rng = np.random.default_rng(seed)
    rows = []
    for episode in range(episodes):
        obs, _ = env.reset(seed=seed * 1000 + episode)
        held, hold_left, done = 0.0, 0, False
        while not done:
            if behaviour == "random":
                action = rng.choice(LEVELS)
            elif behaviour == "held":
                if hold_left == 0:
                    held, hold_left = rng.choice(LEVELS), int(rng.integers(10, 201))
                action, hold_left = held, hold_left - 1
            else:
                if env_id == TASKS[0]:  # the cart moves the pole's pivot: push with -(pole's angular velocity x cos)
                    push = -obs[4] * obs[1]
                else:
                    push = obs[ACTUATED_VELOCITY[env_id]]
                action = 1.0 if push >= 0 else -1.0
            obs, _, terminated, truncated, _ = env.step(np.array([action]))
            rows.append(obs)
            done = terminated or truncated
    env.close()
    return np.asarray(rows)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--tasks", nargs="+", default=list(TASKS), choices=list(TASKS))
    args = parser.parse_args(argv)
    register_dm_control_envs()
    import gymnasium as gym

    behaviours = ("random", "held", "pump")
    for env_id in args.tasks:
        keys = observation_keys(gym.make(env_id).observation_space)
        names = [f"{key}[{i}]" for key, size in keys for i in range(size)]
        data = {b: rollouts(env_id, b, args.episodes, seed) for seed, b in enumerate(behaviours)}
        every = np.concatenate(list(data.values()))
        print(f"## {env_id}: observation_keys {keys}, {args.episodes} episodes per behaviour, {len(every)} steps")
        print("| dimension | min | max | " + " | ".join(f"{b} min, max" for b in behaviours) + " | 0.5 % | 99.5 % |")
        print("|---|---:|---:|" + "---|" * len(behaviours) + "---:|---:|")
        low, high = np.percentile(every, [0.5, 99.5], axis=0)
        for d, name in enumerate(names):
            per = " | ".join(f"{data[b][:, d].min():.3f}, {data[b][:, d].max():.3f}" for b in behaviours)
            print(
                f"| {name} | {every[:, d].min():.3f} | {every[:, d].max():.3f} | {per} | {low[d]:.3f} | {high[d]:.3f} |"
            )
        print()


if __name__ == "__main__":
    main()
