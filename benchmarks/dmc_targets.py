"""dm_control's swing-up tasks with nothing but the env id: SarsaLambda and ERSigma, beside published DDPG and SAC.

    nice -n 5 python benchmarks/dmc_targets.py [--algos sarsa_lambda er_sigma] [--tasks ...] [--seeds 0 1 2 3 4]
        [--steps 500000] [--out results/measured/dmc_targets]
    python benchmarks/dmc_targets.py --summarize [--out ...]

Each run is what a new user writes, ``Algo("TileQ", "dm_control/<task>-v0", seed=seed).learn(500_000)``: the class
defaults, 7 torque levels from -1 to 1, and sb3-er's tiling for the id (sb3_er/data/tilings.yml). It learns in chunks
of ``--every`` steps (a multiple of the tasks' 1,000-step episodes, so a chunk ends with an episode); after each, 3
greedy episodes (``evaluate_policy(deterministic=True)``, a fresh env reset with seed 1000 + seed) give a point of
the learning curve, and after the last 10 give the return reached. The steps it took: the first point of the curve
at 90 % of that return or more.

Resumable per chunk: after every chunk the model (and ERSigma's replay buffer) is saved under
``<out>/checkpoints/`` (not committed) and the run's JSON under ``<out>/runs/<task>/<algo>/seed_<n>.json`` holds the
curve so far; a rerun skips finished runs and continues an unfinished one from its last chunk (the env then starts a
new episode from a fresh reset, which the JSON records as ``resumed_at``). The JSON holds the code version of every
chunk and what the value watch saw (how many values left the possible returns, and the first). ``--summarize``
writes summary.md, runs.json (the table's figures) and the curves (curves.png) from the runs. Runs go one after
another in this process, seeds outermost, so the first seeds of every task and algorithm finish first.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

TASKS = ("dm_control/pendulum-swingup-v0", "dm_control/cartpole-swingup-v0", "dm_control/acrobot-swingup-v0")
ALGOS = ("sarsa_lambda", "er_sigma")
STEPS = 500_000
EVERY = 50_000
CURVE_EPISODES = 3
FINAL_EPISODES = 10
#: The steps a run took: the first point of its curve at this fraction of the return it reached, or more.
REACHED_FRACTION = 0.9
OUT = Path(__file__).resolve().parents[1] / "results" / "measured" / "dmc_targets"

#: Published returns (of 1,000) on the same tasks, state observations, with their sources. Each: (method, return,
#: environment steps it was measured at, source). Only figures whose source states them; the suite's tech report
#: (Tassa et al. 2018, arXiv:1801.00690, section 6) shows A3C, DDPG and D4PG learning curves over 1e8 steps for all
#: three tasks, but no figure of it could be read here, so none is copied from it.
PUBLISHED: dict[str, list[tuple[str, str, str, str]]] = {
    "dm_control/acrobot-swingup-v0": [
        (
            "DDPG (Stable-Baselines3, rl-zoo; the suite's task with 1,000-step episodes as AcrobotSwingupDMC-v0)",
            "63.99 +/- 45.62 (mean_reward of its model card)",
            "not stated on the card",
            "https://huggingface.co/qgallouedec/ddpg-AcrobotSwingupDMC-v0 (model card, README.md)",
        ),
    ],
}


def run_path(out: Path, task: str, label: str, seed: int) -> Path:
    """``<out>/runs/<task>/<label>/seed_<seed>.json``; the label is the algorithm (or a screen's candidate)."""
    return out / "runs" / task.split("/")[1] / label / f"seed_{seed}.json"


def greedy_returns(model, task: str, seed: int, episodes: int) -> list[float]:
    """Returns of ``episodes`` greedy episodes on a fresh env reset with seed 1000 + seed."""
    import gymnasium as gym
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.monitor import Monitor

    env = Monitor(gym.wrappers.FlattenObservation(gym.make(task)))
    env.reset(seed=1000 + seed)
    returns, _ = evaluate_policy(model, env, n_eval_episodes=episodes, deterministic=True, return_episode_rewards=True)
    env.close()
    return [float(r) for r in returns]


def random_baseline(task: str, out: Path, episodes: int = FINAL_EPISODES) -> dict[str, Any]:
    """Returns of a uniformly random choice among the 7 default torque levels on the evaluation's starts (a fresh env
    reset with seed 1000, then ``episodes`` episodes), written once to ``<out>/runs/<task>/random.json``."""
    import gymnasium as gym
    import numpy as np

    from sb3_er.common.atomic import write_atomically
    from sb3_er.common.dict_observations import register_dm_control_envs

    path = out / "runs" / task.split("/")[1] / "random.json"
    if path.is_file():
        return json.loads(path.read_text())
    register_dm_control_envs()
    env = gym.make(task)
    env.reset(seed=1000)
    rng = np.random.default_rng(0)
    levels = np.linspace(-1.0, 1.0, 7)
    returns = []
    for _ in range(episodes):
        env.reset()
        done, total = False, 0.0
        while not done:
            _, reward, terminated, truncated, _ = env.step(rng.choice(levels, size=(1,)))
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
    record = {"task": task, "returns": returns, "mean_return": statistics.fmean(returns)}
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomically(path, json.dumps(record, indent=1))
    return record


def steps_to_reach(curve: list[dict[str, Any]], reached: float) -> int | None:
    """The first step of ``curve`` whose mean greedy return is at ``REACHED_FRACTION`` of ``reached`` or more."""
    for point in curve:
        if point["mean_return"] >= REACHED_FRACTION * reached:
            return point["steps"]
    return None


def run(
    task: str,
    algo: str,
    seed: int,
    steps: int,
    every: int,
    out: Path,
    policy_kwargs: dict | None = None,
    label: str | None = None,
    final_episodes: int = FINAL_EPISODES,
) -> dict[str, Any]:
    """Run (or continue) one run; returns its record. ``policy_kwargs`` (a tiling screen's candidate, filed under
    ``label``) default to none: sb3-er's tiling for the id. ``final_episodes`` greedy episodes give the return
    reached."""
    from sb3_er.common.atomic import write_atomically
    from sb3_er.common.dict_observations import register_dm_control_envs
    from sb3_er.experiments.records import code_version, dependency_versions
    from sb3_er.zoo import algorithm_classes

    register_dm_control_envs()
    path = run_path(out, task, label or algo, seed)
    record = json.loads(path.read_text()) if path.is_file() else None
    if record is not None and record.get("finished"):
        return record
    checkpoint = out / "checkpoints" / path.relative_to(out / "runs").with_suffix("")
    cls = algorithm_classes()[algo]
    kwargs = {} if policy_kwargs is None else {"policy_kwargs": dict(policy_kwargs)}
    if record is not None and (checkpoint / "model.zip").is_file():
        model = cls.load(checkpoint / "model.zip", env=task)
        if (checkpoint / "buffer.npz").is_file():
            model.load_replay_buffer(checkpoint / "buffer.npz")
        record["resumed_at"] = record.get("resumed_at", []) + [model.num_timesteps]
    else:
        model = cls("TileQ", task, seed=seed, **kwargs)
        record = {
            "task": task,
            "algo": algo,
            "label": label or algo,
            "seed": seed,
            "steps": steps,
            "every": every,
            "policy_kwargs": policy_kwargs,
            "curve": [],
            "learn_cpu_s": 0.0,
            "chunks": [],
            "dependencies": dependency_versions(),
        }
    if record["steps"] != steps or record["every"] != every:
        raise SystemExit(f"{path} was started with --steps {record['steps']} --every {record['every']}")
    code = code_version()
    while model.num_timesteps < steps:
        cpu = time.process_time()
        outside = model.values_out_of_range  # the watch's count, from 0 again after a resume's load
        model.learn(min(every, steps - model.num_timesteps), reset_num_timesteps=False)
        record["learn_cpu_s"] += time.process_time() - cpu
        record["values_out_of_range"] = record.get("values_out_of_range", 0) + model.values_out_of_range - outside
        record["value_bounds"] = list(model.value_bounds)
        if model.value_excursion is not None and record.get("first_value_excursion") is None:
            record["first_value_excursion"] = model.value_excursion
        last = model.num_timesteps >= steps
        returns = greedy_returns(model, task, seed, final_episodes if last else CURVE_EPISODES)
        record["curve"].append(
            {"steps": int(model.num_timesteps), "mean_return": statistics.fmean(returns), "returns": returns}
        )
        record["chunks"].append(
            {
                "steps": int(model.num_timesteps),
                "code_sha256": code["code_sha256"],
                "git_commit": code["git_commit"],
                "git_dirty": code["git_dirty"],
            }
        )
        if last:
            record["reached"] = statistics.fmean(returns)
            record["steps_to_reach"] = steps_to_reach(record["curve"], record["reached"])
            record["episodes"] = int(model._episode_num)
            record["finished"] = True
        else:
            checkpoint.mkdir(parents=True, exist_ok=True)
            model.save(checkpoint / "model.zip")
            if hasattr(model, "save_replay_buffer") and getattr(model, "replay_buffer", None) is not None:
                model.save_replay_buffer(checkpoint / "buffer.npz")
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomically(path, json.dumps(record, indent=1))
        print(
            f"{task} {algo} seed {seed}: {model.num_timesteps} steps, "
            f"greedy mean {record['curve'][-1]['mean_return']:.1f}"
            f", {record['learn_cpu_s']:.0f} learn CPU s",
            flush=True,
        )
    return record


def records(out: Path) -> list[dict[str, Any]]:
    return [json.loads(p.read_text()) for p in sorted((out / "runs").glob("*/*/seed_*.json"))]


def _outside(record: dict[str, Any]) -> str:
    """The summary's cell of a run's values outside the possible returns ("not recorded" for a run without them)."""
    if "values_out_of_range" not in record:
        return "not recorded"
    count = record["values_out_of_range"]
    first = record.get("first_value_excursion")
    return f"{count:,}" + (f" (first: {first['value']:.4g} at step {first['step']:,})" if count and first else "")


def summarize(out: Path) -> None:
    """summary.md, runs.json and curves.png from the runs under ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sb3_er.common.atomic import write_atomically

    runs = records(out)
    lines = [
        "# dm_control swing-up tasks with the defaults",
        "",
        f'Generated by `python benchmarks/dmc_targets.py --summarize` from runs/. `Algo("TileQ", env_id, '
        f"seed=seed).learn(steps)`: the class defaults, sb3-er's tiling for the id, 7 torque levels. Return "
        f"reached: mean of {FINAL_EPISODES} greedy episodes after the last step (of 1,000); steps it took: the "
        f"first point of the curve (every {EVERY:,} steps, {CURVE_EPISODES} greedy episodes) at "
        f"{REACHED_FRACTION:.0%} of it. Unfinished runs show their last point.",
        "",
        "Values outside the possible returns: how many targets and Q-values the value watch saw outside the "
        "returns the suite's rewards make possible ([0, 1] a step, which sb3-er's flattening of a dm_control/ id "
        "declares: [0, 100] at gamma 0.99, widened by the initial values), and the first one with its step; a "
        "run with any has left the regime its learner is meant for.",
        "",
        "| task | algorithm | seed | steps run | return reached | steps it took | learn CPU s | values outside the "
        "possible returns (first: value at step) |",
        "|---|---|---:|---:|---:|---:|---:|---|",
    ]
    findings = []
    for r in sorted(runs, key=lambda r: (r["task"], r["algo"], r["seed"])):
        last = r["curve"][-1] if r["curve"] else None
        reached = (
            f"{r['reached']:.1f}"
            if r.get("finished")
            else (f"({last['mean_return']:.1f}, unfinished)" if last else "-")
        )
        took = f"{r['steps_to_reach']:,}" if r.get("steps_to_reach") is not None else "-"
        lines.append(
            f"| {r['task'].split('/')[1]} | {r['algo']} | {r['seed']} | {last['steps'] if last else 0:,} | "
            f"{reached} | {took} | {r['learn_cpu_s']:.0f} | {_outside(r)} |"
        )
        findings.append(
            {
                "task": r["task"],
                "algo": r["algo"],
                "seed": r["seed"],
                "finished": bool(r.get("finished")),
                "steps_run": last["steps"] if last else 0,
                "reached": r.get("reached"),
                "steps_to_reach": r.get("steps_to_reach"),
                "values_out_of_range": r.get("values_out_of_range"),
            }
        )
    lines += [
        "",
        "Published figures on the same tasks (state observations):",
        "",
        "| task | method | return | at steps | source |",
        "|---|---|---:|---:|---|",
    ]
    for task, entries in PUBLISHED.items():
        for method, value, at, source in entries:
            lines.append(f"| {task.split('/')[1]} | {method} | {value} | {at} | {source} |")
    versions = sorted({c["code_sha256"][:10] for r in runs for c in r["chunks"]})
    lines += [
        "",
        f"Code versions (code_sha256, first 10 hex digits) of these runs: {', '.join(versions)}.",
        "",
        "Figure: `curves.png` (the learning curves, every run; the dashed line is the random policy).",
    ]
    baselines = {
        t: json.loads(p.read_text()) for t in TASKS if (p := out / "runs" / t.split("/")[1] / "random.json").is_file()
    }
    if baselines:
        lines[-1:-1] = [
            "A random choice among the 7 torque levels, mean of "
            f"{FINAL_EPISODES} episodes on the same starts: "
            + ", ".join(f"{t.split('/')[1]} {b['mean_return']:.1f}" for t, b in baselines.items())
            + ".",
            "",
        ]
    tasks = [t for t in TASKS if any(r["task"] == t for r in runs)]
    if tasks:
        figure, axes = plt.subplots(1, len(tasks), figsize=(4.2 * len(tasks), 3.4), squeeze=False)
        for ax, task in zip(axes[0], tasks, strict=True):
            for algo, colour in zip(ALGOS, ("tab:blue", "tab:orange"), strict=True):
                for r in (r for r in runs if r["task"] == task and r["algo"] == algo):
                    ax.plot(
                        [p["steps"] for p in r["curve"]],
                        [p["mean_return"] for p in r["curve"]],
                        color=colour,
                        alpha=0.8,
                        marker=".",
                        label=f"{algo}"
                        if r["seed"] == min(x["seed"] for x in runs if x["task"] == task and x["algo"] == algo)
                        else None,
                    )
            if task in baselines:
                ax.axhline(
                    baselines[task]["mean_return"],
                    color="grey",
                    linestyle="--",
                    linewidth=1,
                    label="random torques" if task == tasks[0] else None,
                )
            ax.set_title(task.split("/")[1])
            ax.set_xlabel("steps")
            ax.set_ylim(0, 1000)
            ax.grid(alpha=0.3)
        axes[0][0].set_ylabel("greedy return (of 1,000)")
        axes[0][0].legend(loc="upper left", fontsize=8)
        figure.tight_layout()
        figure.savefig(out / "curves.png", dpi=110)
    write_atomically(out / "summary.md", "\n".join(lines) + "\n")
    write_atomically(out / "runs.json", json.dumps({"runs": findings, "published": PUBLISHED}, indent=1) + "\n")
    print("\n".join(lines))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--algos", nargs="+", default=list(ALGOS), choices=list(ALGOS))
    parser.add_argument("--tasks", nargs="+", default=list(TASKS), choices=list(TASKS))
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4])
    parser.add_argument("--steps", type=int, default=STEPS)
    parser.add_argument("--every", type=int, default=EVERY)
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--summarize", action="store_true")
    args = parser.parse_args(argv)
    if args.summarize:
        summarize(args.out)
        return
    if args.every % 1000:
        raise SystemExit("--every must be a multiple of the tasks' 1,000-step episodes")
    for task in args.tasks:
        random_baseline(task, args.out)
    for seed in args.seeds:
        for task in args.tasks:
            for algo in args.algos:
                run(task, algo, seed, args.steps, args.every, args.out)


if __name__ == "__main__":
    main()
