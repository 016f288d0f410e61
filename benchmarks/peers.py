"""sb3-er beside its peers on Gymnasium's classic control: SB3's DQN with rl-zoo's tuned hyperparameters, and
MushroomRL's tile-coded SARSA(lambda) (issue 12); on the continuous-action tasks, SB3's SAC with rl-zoo's tuned
hyperparameters (issue 26).

    python benchmarks/peers.py                                   # 5 seeds of everything (MushroomRL venv built once)
    python benchmarks/peers.py --seeds 1 --budget 3000 --methods sarsa_lambda dqn --envs CartPole-v1   # tiny
    python benchmarks/peers.py --build-mushroom                  # only build MushroomRL's venv
    python benchmarks/peers.py --json peers.json                 # resumable: runs already in peers.json are skipped
    python benchmarks/peers.py --envs Pendulum-v1 MountainCarContinuous-v0 --methods sarsa_lambda er_sigma sac

Methods (``--methods``):
- ``sarsa_lambda``, ``er_sigma``: sb3-er's ``SarsaLambda`` and ``ERSigma`` with their class defaults and sb3-er's
  tilings for these ids (``sb3_er/data/tilings.yml``; on the continuous-action tasks 7 torque levels per action
  dimension, both bounds included); 100,000 steps, ``learn()``'s default.
- ``dqn``: Stable-Baselines3's DQN with rl-zoo's tuned hyperparameters, read from the installed rl_zoo3 package
  (``rl_zoo3/hyperparams/dqn.yml``); rl-zoo's ``n_timesteps`` (CartPole-v1 50,000, MountainCar-v0 120,000, Acrobot-v1
  100,000). Torch uses one thread. Discrete-action tasks only.
- ``sac``: Stable-Baselines3's SAC with rl-zoo's tuned hyperparameters (``rl_zoo3/hyperparams/sac.yml``) and its
  ``n_timesteps`` (Pendulum-v1 20,000, MountainCarContinuous-v0 50,000); continuous-action tasks only. Torch uses one
  thread.
- ``mushroom``: MushroomRL 1.10.1's ``SARSALambdaContinuous`` on its ``Tiles.generate`` tilings with the same number of
  tilings and displacements (2d + 1)k / N (``uniform=False``, Miller et al.'s asymmetric offsets as ours), with the
  number of tiles per dimension whose width comes closest to ours over the observation range (CartPole's unbounded
  velocities get +-MUSHROOM_VELOCITY_RANGE; the grid is anchored at the range, ours at 0), and sb3-er's default alpha
  (per weight alpha / N), gamma, lambda and epsilon; 100,000 steps. What we cannot make equal: its trace accumulates
  (ours replaces and drops traces below 0.01), its features and trace are dense vectors over all weights, greedy ties
  are broken at random (ours: lowest index), and beyond the range a tiling contributes no feature. MushroomRL pins
  old releases and wraps the old ``gym``, so it runs in its own venv (``--mushroom-venv``, default
  ``~/.cache/sb3-er/mushroom-venv``, built on first use with CPU torch first and the pins of MUSHROOM_PINS), in a
  subprocess, behind a small Gymnasium adapter (``_MushroomGymnasium``). Discrete-action tasks only.

A method is run only on the tasks of its kind (``--methods`` and ``--envs`` pair them up).

Protocol. Every (method, env, seed) runs alone in a fresh subprocess, one after another, so that its CPU time and peak
memory (the child's maximum resident set size, ``ru_maxrss``) are its own. Every ``--eval-freq`` environment steps the
greedy policy plays ``--eval-episodes`` episodes on a separate env; *steps to threshold* is the first such point whose
mean return reaches Gymnasium's ``reward_threshold`` (CartPole-v1 475, MountainCar-v0 -110, Acrobot-v1 -100,
MountainCarContinuous-v0 90; Pendulum-v1 has none), and *steps to target* the first to reach the issues' target level
(450, -140, -120; Pendulum-v1 -200, MountainCarContinuous-v0 90). The *final return* is the mean over
``--final-episodes`` (20) greedy episodes after learning (SB3's ``evaluate_policy(deterministic=True)``; for
MushroomRL the same loop over Q's argmax) on an env reset with seed 1000 + seed. Wall and CPU seconds count learning
only, without the evaluations; steps/s is steps per CPU second. Memory: the peak RSS of the run, and how far it rose
above the RSS after imports and env creation (the learner's own memory).

With ``--json FILE`` every result is written to FILE as soon as its run ends, and runs already in FILE (same env,
method, seed and budget) are skipped, so an interrupted benchmark resumes; the tables then cover every result in FILE.

The first table has one row per (env, method): medians over seeds for the steps (with how many seeds got there), mean
and standard deviation over seeds of the final return, medians of the rest. The second lists every seed.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

DISCRETE_ENVS = ("CartPole-v1", "MountainCar-v0", "Acrobot-v1")
CONTINUOUS_ENVS = ("Pendulum-v1", "MountainCarContinuous-v0")
ENVS = DISCRETE_ENVS + CONTINUOUS_ENVS
METHODS = ("sarsa_lambda", "er_sigma", "dqn", "mushroom", "sac")
METHOD_LABELS = {
    "sarsa_lambda": "sb3-er SarsaLambda",
    "er_sigma": "sb3-er ERSigma",
    "dqn": "SB3 DQN (rl-zoo tuned)",
    "mushroom": "MushroomRL SARSA(λ)",
    "sac": "SB3 SAC (rl-zoo tuned)",
}
#: The tasks each method runs on: the peers are for one kind of action space each.
METHOD_ENVS = {
    "sarsa_lambda": ENVS,
    "er_sigma": ENVS,
    "dqn": DISCRETE_ENVS,
    "mushroom": DISCRETE_ENVS,
    "sac": CONTINUOUS_ENVS,
}
#: SB3's algorithm of each rl-zoo peer.
RL_ZOO_PEERS = ("dqn", "sac")
#: Gymnasium's reward_threshold of each env (checked against env.spec at run time; Pendulum-v1 has none).
THRESHOLDS = {
    "CartPole-v1": 475.0,
    "MountainCar-v0": -110.0,
    "Acrobot-v1": -100.0,
    "Pendulum-v1": None,
    "MountainCarContinuous-v0": 90.0,
}
#: The issues' target levels for the greedy return after 100,000 steps (issue 12: discrete; issue 26: continuous).
TARGETS = {
    "CartPole-v1": 450.0,
    "MountainCar-v0": -140.0,
    "Acrobot-v1": -120.0,
    "Pendulum-v1": -200.0,
    "MountainCarContinuous-v0": 90.0,
}
DEFAULT_BUDGET = 100_000
#: MushroomRL's tiles need a finite range: CartPole's velocities get +-this (|velocities| of learning runs stay within).
MUSHROOM_VELOCITY_RANGE = 4.0
#: CartPole's cart position and pole angle end the episode beyond +-2.4 and +-12 degrees: MushroomRL tiles that range.
CARTPOLE_RANGE = (
    (-2.4, 2.4),
    (-MUSHROOM_VELOCITY_RANGE, MUSHROOM_VELOCITY_RANGE),
    (-0.2095, 0.2095),
    (-MUSHROOM_VELOCITY_RANGE, MUSHROOM_VELOCITY_RANGE),
)
#: A combination that installs from PyPI with this machine's CPU torch: mushroom-rl 1.10.2 pins torch 2.5.1 (a CUDA
#: build from PyPI), 1.10.1 does not pin torch; numpy < 2 for its old code.
MUSHROOM_TORCH = "torch==2.13.0"
MUSHROOM_PINS = (
    "mushroom-rl==1.10.1",
    "numpy==1.26.4",
    "scipy==1.17.1",
    "scikit-learn==1.9.1",
    "matplotlib==3.11.2",
    "opencv-python==4.11.0.86",
    "pygame==2.6.1",
    "gymnasium==1.4.0",
)
DEFAULT_MUSHROOM_VENV = Path(
    os.environ.get("SB3_ER_MUSHROOM_VENV", Path.home() / ".cache" / "sb3-er" / "mushroom-venv")
)
RESULT_PREFIX = "PEERS_RESULT "


# --- measurements shared by every worker (benchmarks/sample_efficiency.py uses them too) ---------------------------


def peak_rss_mb() -> float:
    """Peak resident set size of this process so far, in MB (Linux reports KB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


class Clock:
    """Wall and CPU time of a stretch, minus the evaluations inside it: start it before learning, run every
    evaluation through :meth:`evaluation`, and read :meth:`learning` after learning."""

    def __init__(self):
        self.wall0, self.cpu0 = time.perf_counter(), time.process_time()
        self.eval_wall = self.eval_cpu = 0.0

    def evaluation(self, function, *args):
        wall, cpu = time.perf_counter(), time.process_time()
        result = function(*args)
        self.eval_wall += time.perf_counter() - wall
        self.eval_cpu += time.process_time() - cpu
        return result

    def learning(self) -> tuple[float, float]:
        return (time.perf_counter() - self.wall0 - self.eval_wall, time.process_time() - self.cpu0 - self.eval_cpu)


def first_reaching(evaluations: list[tuple[int, float]], level):
    """The step of the first (step, value) of `evaluations` whose value reaches `level`; None if none does or the
    level is None."""
    if level is None:
        return None
    return next((step for step, value in evaluations if value >= level), None)


def _result(
    config: dict,
    evaluations,
    final_returns,
    learning: tuple[float, float],
    baseline_mb: float,
    episodes: int,
    extra=None,
) -> dict:
    wall, cpu = learning
    threshold, target = THRESHOLDS[config["env"]], TARGETS[config["env"]]
    return {
        **config,
        "threshold": threshold,
        "target": target,
        "evaluations": evaluations,
        "steps_to_threshold": first_reaching(evaluations, threshold),
        "steps_to_target": first_reaching(evaluations, target),
        "final_returns": [float(r) for r in final_returns],
        "final_mean": float(statistics.fmean(final_returns)),
        "final_median": float(statistics.median(final_returns)),
        "learn_wall_s": wall,
        "learn_cpu_s": cpu,
        "steps_per_cpu_s": config["budget"] / max(cpu, 1e-9),
        "peak_rss_mb": peak_rss_mb(),
        "baseline_rss_mb": baseline_mb,
        "episodes": episodes,
        **(extra or {}),
    }


# --- sb3-er and DQN (this venv) ------------------------------------------------------------------------------------


def rl_zoo_dqn_hyperparameters(env_id: str) -> tuple[int, dict]:
    """rl-zoo's tuned DQN settings for env_id from the installed rl_zoo3 package: (n_timesteps, DQN kwargs)."""
    return rl_zoo_hyperparameters("dqn", env_id)


def _rl_zoo_file(algo: str) -> dict:
    import rl_zoo3
    import yaml

    with open(Path(rl_zoo3.__file__).parent / "hyperparams" / f"{algo}.yml") as stream:
        return yaml.safe_load(stream)


def rl_zoo_env_ids(algo: str) -> set[str]:
    """The env ids rl-zoo has tuned settings of SB3's ``algo`` (dqn, sac) for, in the installed rl_zoo3 package."""
    return {key for key in _rl_zoo_file(algo) if key not in ("default", "atari")}


def rl_zoo_hyperparameters(algo: str, env_id: str) -> tuple[int, dict]:
    """rl-zoo's tuned settings of SB3's ``algo`` (dqn, sac) for env_id from the installed rl_zoo3 package:
    (n_timesteps, the algorithm's kwargs)."""
    hyperparameters = dict(_rl_zoo_file(algo)[env_id])
    n_timesteps = int(hyperparameters.pop("n_timesteps"))
    hyperparameters.pop("policy")
    if isinstance(hyperparameters.get("policy_kwargs"), str):  # rl-zoo evaluates this string the same way
        hyperparameters["policy_kwargs"] = eval(hyperparameters["policy_kwargs"], {"__builtins__": {}, "dict": dict})
    return n_timesteps, hyperparameters


def rl_zoo_model(algo: str, env, seed: int):
    """SB3's ``algo`` (dqn, sac) with rl-zoo's tuned settings for ``env``'s id, on the CPU, torch on one thread."""
    import torch
    from stable_baselines3 import DQN, SAC

    torch.set_num_threads(1)
    _, kwargs = rl_zoo_hyperparameters(algo, env.spec.id)
    return {"dqn": DQN, "sac": SAC}[algo]("MlpPolicy", env, seed=seed, device="cpu", **kwargs)


def greedy_evaluations(model, eval_env, episodes: int, every: int, budget: int, clock: Clock, evaluations: list):
    """An SB3 callback that appends ``(step, mean greedy return)`` to `evaluations` every `every` environment steps and
    at step `budget`: the mean over `episodes` episodes of ``evaluate_policy(model, eval_env, deterministic=True)``,
    timed by `clock` as evaluation (so that it is not counted as learning).

    :param model: the learning model.
    :param eval_env: the env the greedy episodes run on (not the learning env).
    :param episodes: episodes per evaluation.
    :param every: environment steps between evaluations.
    :param budget: the run's last step, evaluated too.
    :param clock: the run's clock.
    :param evaluations: the list the ``(step, mean return)`` pairs go to.
    """
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.evaluation import evaluate_policy

    def greedy_mean() -> float:
        mean, _ = evaluate_policy(model, eval_env, n_eval_episodes=episodes, deterministic=True)
        return float(mean)

    class Evaluations(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps % every == 0 or self.num_timesteps == budget:
                evaluations.append((self.num_timesteps, clock.evaluation(greedy_mean)))
            return True

    return Evaluations()


def _run_sb3(config: dict) -> dict:
    import torch

    torch.set_num_threads(1)
    import gymnasium as gym
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.monitor import Monitor

    env_id, seed, method = config["env"], config["seed"], config["method"]
    train_env, eval_env, final_env = (Monitor(gym.make(env_id)) for _ in range(3))
    if train_env.spec.reward_threshold != THRESHOLDS[env_id]:
        raise RuntimeError(
            f"{env_id}'s reward_threshold is {train_env.spec.reward_threshold}, "
            f"not {THRESHOLDS[env_id]}: update THRESHOLDS"
        )
    eval_env.reset(seed=2000 + seed)
    final_env.reset(seed=1000 + seed)
    baseline = peak_rss_mb()
    if method in RL_ZOO_PEERS:
        model = rl_zoo_model(method, train_env, seed)
    else:  # imported only here, so that DQN's memory does not count sb3-er's imports
        from sb3_er import ERSigma, SarsaLambda

        model = {"sarsa_lambda": SarsaLambda, "er_sigma": ERSigma}[method]("TileQ", train_env, seed=seed)
    clock = Clock()
    evaluations = []
    callback = greedy_evaluations(
        model, eval_env, config["eval_episodes"], config["eval_freq"], config["budget"], clock, evaluations
    )
    model.learn(config["budget"], callback=callback)
    learning = clock.learning()
    returns, _ = evaluate_policy(
        model, final_env, n_eval_episodes=config["final_episodes"], deterministic=True, return_episode_rewards=True
    )
    episodes = len(train_env.get_episode_rewards())
    extra = {"tiling": model.policy_kwargs if method not in RL_ZOO_PEERS else None}
    return _result(config, evaluations, returns, learning, baseline, episodes, extra)


# --- MushroomRL (its own venv) -------------------------------------------------------------------------------------


def mushroom_tiles(n_tilings: int, tile_widths, low, high) -> list[int]:
    """Tiles per dimension for MushroomRL's ``Tiles.generate(n_tilings, n_tiles, low, high)`` whose width comes
    closest to ``tile_widths``: its tiles are (high - low) / (n - (N - 1) / N) wide (mushroom_rl/features/tiles)."""
    spill = (n_tilings - 1) / n_tilings
    return [max(1, round((h - lo) / w + spill)) for w, lo, h in zip(tile_widths, low, high, strict=True)]


def mushroom_widths(n_tilings: int, n_tiles, low, high) -> list[float]:
    """The tile widths of ``Tiles.generate(n_tilings, n_tiles, low, high)``."""
    spill = (n_tilings - 1) / n_tilings
    return [(h - lo) / (n - spill) for n, lo, h in zip(n_tiles, low, high, strict=True)]


def _run_mushroom(config: dict) -> dict:
    import gymnasium as gym
    import numpy as np
    from mushroom_rl.algorithms.value import SARSALambdaContinuous
    from mushroom_rl.approximators.parametric import LinearApproximator
    from mushroom_rl.core import Core, Environment, MDPInfo
    from mushroom_rl.features import Features
    from mushroom_rl.features.tiles import Tiles
    from mushroom_rl.policy import EpsGreedy
    from mushroom_rl.utils import spaces
    from mushroom_rl.utils.parameters import Parameter

    class _MushroomGymnasium(Environment):
        """A Gymnasium env as a MushroomRL Environment: absorbing = terminated; time limits end the episode at the
        horizon (the spec's max_episode_steps), where MushroomRL bootstraps, as sb3-er does at a truncation."""

        def __init__(self, env_id: str, gamma: float, seed: int):
            self.env = gym.make(env_id)
            self._seed = seed
            box = self.env.observation_space
            info = MDPInfo(
                spaces.Box(box.low.astype(np.float64), box.high.astype(np.float64)),
                spaces.Discrete(int(self.env.action_space.n)),
                gamma,
                self.env.spec.max_episode_steps,
            )
            super().__init__(info)

        def reset(self, state=None):
            obs, _ = self.env.reset(seed=self._seed)
            self._seed = None
            return np.asarray(obs, dtype=np.float64)

        def step(self, action):
            obs, reward, terminated, _, info = self.env.step(int(np.asarray(action).reshape(-1)[0]))
            return np.asarray(obs, dtype=np.float64), float(reward), bool(terminated), info

    env_id, seed, tiling, hyper = config["env"], config["seed"], config["tiling"], config["hyperparameters"]
    np.random.seed(seed)  # noqa: NPY002 (MushroomRL draws from NumPy's global generator)
    mdp = _MushroomGymnasium(env_id, hyper["gamma"], seed)
    n_tilings = int(tiling["n_tilings"])
    low, high = (np.array(bound, dtype=np.float64) for bound in zip(*tiling["range"], strict=True))
    n_tiles = mushroom_tiles(n_tilings, tiling["tile_widths"], low, high)
    tilings = Tiles.generate(n_tilings, n_tiles, low, high, uniform=False)
    features = Features(tilings=tilings)
    n_actions = mdp.info.action_space.n
    policy = EpsGreedy(epsilon=Parameter(hyper["exploration_rate"]))
    agent = SARSALambdaContinuous(
        mdp.info,
        policy,
        LinearApproximator,
        learning_rate=Parameter(hyper["learning_rate"] / n_tilings),
        lambda_coeff=hyper["trace_lambda"],
        features=features,
        approximator_params={"input_shape": (features.size,), "output_shape": (n_actions,), "n_actions": n_actions},
    )
    baseline = peak_rss_mb()

    def greedy_returns(env, n_episodes: int, reset_seed=None) -> list[float]:
        returns = []
        for episode in range(n_episodes):
            obs, _ = env.reset(seed=reset_seed if episode == 0 else None)
            total, done = 0.0, False
            while not done:
                action = int(np.argmax(agent.Q.predict(features(obs))))
                obs, reward, terminated, truncated, _ = env.step(action)
                total += float(reward)
                done = terminated or truncated
            returns.append(total)
        return returns

    eval_env, final_env = gym.make(env_id), gym.make(env_id)
    eval_env.reset(seed=2000 + seed)
    clock = Clock()
    evaluations = []
    counter = {"steps": 0, "episodes": 0}

    def on_step(samples):
        counter["steps"] += 1
        counter["episodes"] += int(samples[0][-1])
        if counter["steps"] % config["eval_freq"] == 0 or counter["steps"] == config["budget"]:
            value = clock.evaluation(lambda: float(np.mean(greedy_returns(eval_env, config["eval_episodes"]))))
            evaluations.append((counter["steps"], value))

    Core(agent, mdp, callback_step=on_step).learn(n_steps=config["budget"], n_steps_per_fit=1, quiet=True)
    learning = clock.learning()
    returns = greedy_returns(final_env, config["final_episodes"], reset_seed=1000 + seed)
    extra = {
        "mushroom_n_tiles": n_tiles,
        "mushroom_tile_widths": mushroom_widths(n_tilings, n_tiles, low, high),
        "mushroom_features": int(features.size),
    }
    return _result(config, evaluations, returns, learning, baseline, counter["episodes"], extra)


def mushroom_python(venv: Path) -> Path:
    return venv / "bin" / "python"


def mushroom_ready(venv: Path) -> tuple[bool, str]:
    """Whether MushroomRL's venv exists and imports what the benchmark needs; the reason if not."""
    python = mushroom_python(venv)
    if not python.exists():
        return False, f"MushroomRL's venv {venv} is not built (python benchmarks/peers.py --build-mushroom)"
    probe = subprocess.run(
        [str(python), "-c", "import mushroom_rl, gymnasium; print(mushroom_rl.__version__)"],
        check=False,
        capture_output=True,
        text=True,
    )
    if probe.returncode != 0:
        return False, f"MushroomRL's venv {venv} does not import mushroom_rl and gymnasium: {probe.stderr[-500:]}"
    return True, f"mushroom-rl {probe.stdout.strip()} in {venv}"


def build_mushroom_venv(venv: Path) -> None:
    """Create MushroomRL's venv: CPU torch first (from this machine's wheels or PyPI), then the pinned releases."""
    venv.parent.mkdir(parents=True, exist_ok=True)
    print(f"building MushroomRL's venv in {venv} (a few minutes) ...", file=sys.stderr, flush=True)
    subprocess.run([sys.executable, "-m", "venv", "--clear", str(venv)], check=True)
    pip = [str(mushroom_python(venv)), "-m", "pip", "install", "--quiet"]
    subprocess.run([*pip, MUSHROOM_TORCH], check=True)
    subprocess.run([*pip, *MUSHROOM_PINS], check=True)
    ready, reason = mushroom_ready(venv)
    if not ready:
        raise RuntimeError(reason)


# --- the driver ----------------------------------------------------------------------------------------------------


def sb3_er_defaults() -> dict:
    """sb3-er's default alpha, gamma, epsilon and lambda (SarsaLambda's constructor), for MushroomRL."""
    import inspect

    from sb3_er import SarsaLambda
    from sb3_er.common.base_class import TileQAlgorithm

    base = inspect.signature(TileQAlgorithm).parameters
    return {
        "learning_rate": base["learning_rate"].default,
        "gamma": base["gamma"].default,
        "exploration_rate": base["exploration_rate"].default,
        "trace_lambda": inspect.signature(SarsaLambda).parameters["trace_lambda"].default,
    }


def mushroom_tiling(env_id: str) -> dict:
    """sb3-er's tiling for env_id and the finite range MushroomRL's tiles cover."""
    import gymnasium as gym

    from sb3_er.common.tile_coding import package_tilings

    entry = package_tilings()[env_id]
    space = gym.make(env_id).observation_space
    ranges = (
        CARTPOLE_RANGE if env_id == "CartPole-v1" else tuple(zip(space.low.tolist(), space.high.tolist(), strict=True))
    )
    return {"n_tilings": int(entry["n_tilings"]), "tile_widths": list(entry["tile_widths"]), "range": ranges}


#: Thread limits of a worker subprocess: one BLAS/OpenMP/numba thread, so that N workers use N cores.
WORKER_THREADS = {
    name: "1" for name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS", "OPENBLAS_NUM_THREADS")
}


#: The environment variable that tells a worker subprocess its parent's process id (see :func:`end_with_parent`).
PARENT_VARIABLE = "SB3_ER_BENCHMARK_PARENT"


def end_with_parent() -> None:
    """Make this worker subprocess end when the benchmark that started it ends, however it ends (SIGTERM or SIGKILL
    to that process alone, a scheduler's time limit), instead of running on orphaned with its result lost: sb3-er's
    :func:`sb3_er.experiments.lifetime.die_with_parent`, loaded from its file, which needs the standard library only,
    so that it works in the MushroomRL venv too, where sb3-er is not installed. Does nothing in a process that
    :func:`run_in_subprocess` did not start (a worker run by hand).
    """
    parent = os.environ.get(PARENT_VARIABLE)
    if parent is None:
        return
    import importlib.util

    path = Path(__file__).resolve().parents[1] / "sb3_er" / "experiments" / "lifetime.py"
    spec = importlib.util.spec_from_file_location("_sb3_er_lifetime", path)
    lifetime = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(lifetime)
    lifetime.die_with_parent(int(parent))


def run_in_subprocess(
    script: str | Path, config: dict, python: str, prefix: str, what: str, environment: dict | None = None
) -> dict:
    """Run ``python script --worker <config as JSON>`` in a fresh subprocess and return the JSON that its last stdout
    line starting with `prefix` carries; RuntimeError naming `what` and the end of the child's stderr when it fails or
    prints no result.

    :param script: the benchmark script whose ``--worker`` runs one configuration.
    :param config: the run's configuration (JSON-able).
    :param python: the interpreter to run it with.
    :param prefix: the marker of the result line.
    :param what: the run, for the error message.
    :param environment: variables set in the child beside this process's (default None: none), e.g. WORKER_THREADS.

    The child's ``--worker`` calls :func:`end_with_parent` first, so that it ends with this process.
    """
    command = [python, os.path.abspath(script), "--worker", json.dumps(config)]
    environment = {**os.environ, **(environment or {}), PARENT_VARIABLE: str(os.getpid())}
    process = subprocess.run(command, check=False, capture_output=True, text=True, env=environment)
    lines = [line for line in process.stdout.splitlines() if line.startswith(prefix)]
    if process.returncode != 0 or not lines:
        raise RuntimeError(f"{what} failed (exit code {process.returncode}):\n{process.stderr[-3000:]}")
    return json.loads(lines[-1][len(prefix) :])


def run_one(config: dict, python: str) -> dict:
    """One (method, env, seed) in a fresh subprocess; its result dict."""
    what = f"{config['method']} on {config['env']} (seed {config['seed']})"
    return run_in_subprocess(__file__, config, python, RESULT_PREFIX, what)


def _median(values):
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None


def _steps(results, key) -> str:
    if key == "steps_to_threshold" and results[0]["threshold"] is None:
        return "no threshold"
    reached = [r[key] for r in results if r[key] is not None]
    if not reached:
        return f"not reached (0/{len(results)})"
    return f"{statistics.median(reached):,.0f} ({len(reached)}/{len(results)})"


def markdown_tables(results: list[dict]) -> str:
    """The summary table (one row per env and method) and the per-seed table."""
    rows = [
        (
            "| env | method | steps | steps to threshold (seeds) | steps to target (seeds) | final return (mean ± sd "
            "over seeds) | learn wall s | learn CPU s | steps/CPU s | peak RSS MB | above imports MB |"
        ),
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    per_seed = [
        (
            "| env | method | seed | final mean | final median | steps to threshold | steps to target | "
            "learn CPU s | episodes |"
        ),
        "|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    groups: dict[tuple[str, str], list[dict]] = {}
    for result in results:
        groups.setdefault((result["env"], result["method"]), []).append(result)
    for (env_id, method), group in groups.items():
        finals = [r["final_mean"] for r in group]
        spread = statistics.stdev(finals) if len(finals) > 1 else 0.0
        rows.append(
            f"| {env_id} | {METHOD_LABELS[method]} | {group[0]['budget']:,} | {_steps(group, 'steps_to_threshold')} | "
            f"{_steps(group, 'steps_to_target')} | {statistics.fmean(finals):.1f} ± {spread:.1f} | "
            f"{_median([r['learn_wall_s'] for r in group]):.1f} | {_median([r['learn_cpu_s'] for r in group]):.1f} | "
            f"{_median([r['steps_per_cpu_s'] for r in group]):,.0f} | "
            f"{_median([r['peak_rss_mb'] for r in group]):.0f} | "
            f"{_median([r['peak_rss_mb'] - r['baseline_rss_mb'] for r in group]):.0f} |"
        )

        def fmt(v):
            return "-" if v is None else f"{v:,}"

        for r in group:
            per_seed.append(
                f"| {env_id} | {METHOD_LABELS[method]} | {r['seed']} | {r['final_mean']:.1f} | {r['final_median']:.1f} "
                f"| {fmt(r['steps_to_threshold'])} | {fmt(r['steps_to_target'])} | {r['learn_cpu_s']:.1f} | "
                f"{r['episodes']} |"
            )
    return "\n".join(rows) + "\n\n" + "\n".join(per_seed)


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--envs", nargs="+", default=list(ENVS), choices=ENVS)
    parser.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    parser.add_argument("--seeds", type=int, default=5, help="seeds per (env, method) (default 5)")
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument(
        "--budget",
        type=int,
        default=None,
        help="environment steps for every method (default: 100,000; rl-zoo's n_timesteps for DQN and SAC)",
    )
    parser.add_argument("--eval-freq", type=int, default=5000, help="steps between greedy evaluations (default 5000)")
    parser.add_argument("--eval-episodes", type=int, default=10, help="episodes per periodic evaluation (default 10)")
    parser.add_argument("--final-episodes", type=int, default=20, help="episodes of the final evaluation (default 20)")
    parser.add_argument("--mushroom-venv", type=Path, default=DEFAULT_MUSHROOM_VENV)
    parser.add_argument(
        "--no-build",
        action="store_true",
        help="do not build MushroomRL's venv: leave MushroomRL out (with the reason) if it is missing",
    )
    parser.add_argument("--build-mushroom", action="store_true", help="build MushroomRL's venv and exit")
    parser.add_argument(
        "--json",
        type=Path,
        default=None,
        help="write every result to this JSON file as its run ends; runs already in it are skipped "
        "(resume), and the tables cover all of its results",
    )
    parser.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    return parser


def main(argv=None) -> None:
    args = _parser().parse_args(argv)
    if args.worker is not None:
        end_with_parent()
        config = json.loads(args.worker)
        result = _run_mushroom(config) if config["method"] == "mushroom" else _run_sb3(config)
        print(RESULT_PREFIX + json.dumps(result), flush=True)
        return
    if args.build_mushroom:
        build_mushroom_venv(args.mushroom_venv)
        print(mushroom_ready(args.mushroom_venv)[1])
        return
    methods = list(args.methods)
    notes = []
    if "mushroom" in methods:
        ready, reason = mushroom_ready(args.mushroom_venv)
        if not ready and not args.no_build:
            build_mushroom_venv(args.mushroom_venv)
            ready, reason = mushroom_ready(args.mushroom_venv)
        if not ready:
            methods.remove("mushroom")
            notes.append(f"MushroomRL left out: {reason}")
        else:
            notes.append(f"MushroomRL: {reason}")
    hyperparameters = sb3_er_defaults() if "mushroom" in methods else None
    results = json.loads(args.json.read_text()) if args.json is not None and args.json.exists() else []
    done = {(result["env"], result["method"], result["seed"], result["budget"]) for result in results}
    for env_id in args.envs:
        for method in methods:
            if env_id not in METHOD_ENVS[method]:
                continue
            if args.budget is not None:
                budget = args.budget
            elif method in RL_ZOO_PEERS:
                budget = rl_zoo_hyperparameters(method, env_id)[0]
            else:
                budget = DEFAULT_BUDGET
            for seed in range(args.first_seed, args.first_seed + args.seeds):
                if (env_id, method, seed, budget) in done:
                    continue
                config = {
                    "method": method,
                    "env": env_id,
                    "seed": seed,
                    "budget": budget,
                    "eval_freq": args.eval_freq,
                    "eval_episodes": args.eval_episodes,
                    "final_episodes": args.final_episodes,
                }
                python = sys.executable
                if method == "mushroom":
                    config.update(tiling=mushroom_tiling(env_id), hyperparameters=hyperparameters)
                    python = str(mushroom_python(args.mushroom_venv))
                result = run_one(config, python)
                results.append(result)
                if args.json is not None:  # atomically: a killed benchmark keeps every result before the last
                    from sb3_er.experiments.files import write_atomically

                    write_atomically(args.json, json.dumps(results, indent=1))
                print(
                    f"{env_id} {method} seed {seed}: final {result['final_mean']:.1f}, "
                    f"{result['learn_cpu_s']:.1f} CPU s",
                    file=sys.stderr,
                    flush=True,
                )
    print(markdown_tables(results))
    for note in notes:
        print(f"\n{note}")


if __name__ == "__main__":
    main()
