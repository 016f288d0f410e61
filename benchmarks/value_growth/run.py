"""The value-growth mechanism, measured (docs/value_growth.md): regenerates results/measured/value_mechanism/.

    python benchmarks/value_growth/run.py                      # everything, 2 seeds (resumable: finished runs stay)
    python benchmarks/value_growth/run.py --parts figure       # Figure 5.6 and the closed form only (seconds)
    python benchmarks/value_growth/run.py --parts walker --seeds 3 --variants er er_sigma
    python benchmarks/value_growth/run.py --parts pendulum_v1 --seeds 5 --out results/measured/continuous_values \
        --variants er er_sigma er_sigma_volume residual_er_sigma residual_er_sigma_next er_sigma_rate_005

Parts:
- ``figure``: Figure 5.6's self-affecting sample replayed by ER, ER-sigma, residual ER and residual ER-sigma through
  the kernels (``sb3_er.experiments.value_growth.self_affecting_model``), against the closed form, and the limit
  value against the number of tiles s' shares with s.
- ``walker``, ``pendulum``: short learning runs (walker 25,000 steps = 5000 s of learning; pendulum at its default
  reading, velocity tiles 3.3 rad/s, 40 episodes = 60,000 steps) of vanilla ER, ER-sigma and ER-sigma with one
  candidate cause changed at a time (VARIANTS). Every CHECKPOINT steps the stored transitions are instrumented
  (``target_comparison``: the vanilla and the ER-sigma target on the same weights and visits) and at GAIN_AT the
  replay operator's gain with every reward 0 is measured for vanilla ER and each sigma definition (``replay_gain``).
  One CSV of checkpoint rows and one version record (JSON) per run under ``runs/<problem>/<variant>/``.
- ``pendulum_v1``: Gymnasium's Pendulum-v1 with nothing but the env id (sb3-er's tiling for it, 7 torques; 100,000
  steps, instrumented every 10,000), the same instruments plus the median greedy return of 10 episodes at every
  checkpoint (env reset with seed 1000 + seed). Meant for its own folder (``--out``), without the figure part.
Then ``summary.md`` and the figures are written from every run on disk (Figure 5.6's part only where it was computed:
``--parts figure``, or its figure already in the folder).
"""

from __future__ import annotations

import argparse
import datetime
import platform
import socket
import sys
import time
from pathlib import Path

import gymnasium as gym
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from stable_baselines3.common.callbacks import BaseCallback  # noqa: E402
from stable_baselines3.common.evaluation import evaluate_policy  # noqa: E402
from stable_baselines3.common.monitor import Monitor  # noqa: E402

import sb3_er_envs  # noqa: E402,F401  (registers the env ids)
from sb3_er import DivergenceError  # noqa: E402
from sb3_er.experiments import records  # noqa: E402
from sb3_er.experiments import value_growth as vg  # noqa: E402
from sb3_er.zoo import algorithm_classes, model_kwargs  # noqa: E402

OUT = Path("results/measured/value_mechanism")
PROBLEMS = {
    "walker": {
        "env_id": "sb3_er/SimplestWalker-v0",
        "steps": 25_000,
        "checkpoint": 2_500,
        "gain_at": (5_000, 10_000),
        "reward_max": 30.0,
        "reward_min": -50.0,
        "gamma": 0.99,
    },
    "pendulum": {
        "env_id": "sb3_er/PendulumSwingup-v0",
        "steps": 60_000,
        "checkpoint": 6_000,
        "gain_at": (12_000, 24_000),
        "reward_max": 0.0,
        "reward_min": None,
        "gamma": 0.98,
    },
    # Gymnasium's swing-up: the class defaults on the env id alone (gamma 0.99); every reward <= 0, 200 steps an
    # episode, truncated (replay bootstraps there); "eval_episodes": greedy episodes at every checkpoint.
    "pendulum_v1": {
        "env_id": "Pendulum-v1",
        "steps": 100_000,
        "checkpoint": 10_000,
        "gain_at": (10_000, 30_000),
        "reward_max": 0.0,
        "reward_min": None,
        "gamma": 0.99,
        "eval_episodes": 10,
        "class_defaults": True,
        "level": -200.0,
        "reading": "nothing but the env id",
    },
}
#: The problems run when --parts is not given (pendulum_v1 has its own folder).
DEFAULT_PARTS = ("figure", "walker", "pendulum")
# name: (algorithm, constructor overrides, env overrides, what it tests); overrides keyed by problem apply to those
# problems only, and a variant with neither for a problem is not run there.
VARIANTS = {
    "er": ("er", {}, {}, "vanilla ER, the same settings"),
    "er_sigma": ("er_sigma", {}, {}, "ER-σ, the default reading"),
    "er_sigma_memory": (
        "er_sigma",
        {"policy_kwargs": {"memory_size": 2**25}},
        {},
        "hash collisions: 8x the weight memory",
    ),
    "er_sigma_volume": (
        "er_sigma",
        {
            "walker": {"replay_unit": "segment"},
            "pendulum": {"replays_per_stored_trajectory": 1.0},
            "pendulum_v1": {"n_replays": 10},
        },
        {},
        "replay volume: walker footstep segments, pendulum 1 replay per stored trajectory, "
        "Pendulum-v1 10 episodes per phase instead of 100",
    ),
    "er_sigma_worst": ("er_sigma", {"sigma": "worst"}, {}, "σ's definition: the worst case instead of definition 4"),
    "er_sigma_q_learning": ("er_sigma", {"target": "q_learning"}, {}, "greedy a' (no exploratory a')"),
    "residual_er_sigma": ("residual_er_sigma", {}, {}, "residual ER-σ (ζ = 1, the residual term on a_t)"),
    "residual_er_sigma_next": (
        "residual_er_sigma",
        {"residual_action": "next"},
        {},
        "residual ER-σ with the residual term on a_{t+1} (Baird's residual gradient)",
    ),
    "er_sigma_width033": (
        "er_sigma",
        {},
        {"pendulum": {"velocity_tile_width": 0.33}},
        "pendulum: the printed velocity tile width 0.33 rad/s",
    ),
    "er_width033": (
        "er",
        {},
        {"pendulum": {"velocity_tile_width": 0.33}},
        "pendulum: vanilla ER at velocity tile width 0.33 rad/s",
    ),
    "er_sigma_rate_005": (
        "er_sigma",
        {"pendulum_v1": {"learning_rate": 0.05}},
        {},
        "Pendulum-v1: ER-σ at α 0.05 instead of 0.2 (evidence for users, not a default)",
    ),
}
#: The runs whose checkpoints at GAIN_AT also measure the replay operator's gain per sigma definition.
GAIN_VARIANTS = ("er", "er_sigma", "er_sigma_volume")
SIGMAS_FOR_GAIN = (None, "worst", "average_worst", "average", "best")


def _per_problem(overrides: dict, problem: str) -> dict | None:
    """The overrides of `problem` from a per-problem dict ({} when it has none: None), or the common overrides."""
    if overrides and set(overrides) <= set(PROBLEMS):
        return dict(overrides[problem]) if problem in overrides else None
    return dict(overrides)


def applies(problem: str, variant: str) -> bool:
    """Whether `variant` changes anything on `problem` (per-problem overrides name the problems they are for)."""
    _, overrides, env_overrides, _ = VARIANTS[variant]
    return _per_problem(overrides, problem) is not None and _per_problem(env_overrides, problem) is not None


def variant_kwargs(problem: str, variant: str) -> tuple[str, dict, dict]:
    algo, overrides, env_overrides, _ = VARIANTS[variant]
    overrides = _per_problem(overrides, problem) or {}
    if PROBLEMS[problem].get("class_defaults"):  # nothing but the env id, as a new user writes it
        kwargs = {}
    else:
        kwargs = model_kwargs(algo, PROBLEMS[problem]["env_id"])
        kwargs.pop("policy", None)
    policy_kwargs = {**kwargs.pop("policy_kwargs", {}), **overrides.pop("policy_kwargs", {})}
    kwargs.update(overrides, policy_kwargs=policy_kwargs)
    return algo, kwargs, _per_problem(env_overrides, problem) or {}


class Checkpoints(BaseCallback):
    """Every `interval` steps: the target comparison and the value range over the stored transitions; at `gain_at`
    the replay operator's gain per sigma definition."""

    def __init__(
        self,
        interval: int,
        gain_at: tuple[int, ...],
        last: int,
        env_id: str | None = None,
        eval_episodes: int = 0,
        seed: int = 0,
    ):
        super().__init__()
        self.interval, self.gain_at, self.last, self.rows = interval, gain_at, last, []
        self.env_id, self.eval_episodes, self.seed = env_id, eval_episodes, seed

    def _on_step(self) -> bool:
        if self.num_timesteps % self.interval:
            return True
        model = self.model
        comparison = vg.target_comparison(model)
        row = {
            "timesteps": self.num_timesteps,
            "replay_updates": model.replay_updates,
            "replay_phases": model.replay_phases,
            **vg.comparison_summary(comparison),
        }
        keep = ~comparison["terminal"]
        row["min_q_sa"] = float(comparison["q_sa"].min())
        row["mean_max_q_next"] = float(
            (
                (
                    comparison["target_vanilla"][keep]
                    - model.replay_buffer.rewards[vg.stored_transitions(model.replay_buffer)[0]][keep]
                )
                / model.gamma
            ).mean()
        )
        if self.num_timesteps == self.last:  # how many distinct stored tiles share a hashed slot
            buffer = model.replay_buffer
            observations = buffer.observations[vg.stored_transitions(buffer)[0]]
            row["collision_rate"] = model.policy.tile_coder.memory_report(observations)["collision_rate"]
        if self.num_timesteps in self.gain_at:
            for sigma in SIGMAS_FOR_GAIN:
                row[gain_column(sigma)] = vg.replay_gain(model, sigma=sigma)
        row["values_out_of_range"] = model.values_out_of_range
        if self.eval_episodes:
            env = Monitor(gym.make(self.env_id))
            env.reset(seed=1000 + self.seed)
            returns, _ = evaluate_policy(
                model, env, n_eval_episodes=self.eval_episodes, deterministic=True, return_episode_rewards=True
            )
            env.close()
            row["greedy_median"] = float(np.median(returns))
        self.rows.append(row)
        return True


def run(problem: str, variant: str, seed: int, out: Path) -> Path:
    csv = out / "runs" / problem / variant / f"seed_{seed}.csv"
    if csv.is_file():
        return csv
    settings = PROBLEMS[problem]
    algo, kwargs, env_kwargs = variant_kwargs(problem, variant)
    code = records.code_version()
    start = time.perf_counter()
    env = gym.make(settings["env_id"], **env_kwargs)
    model = algorithm_classes()[algo]("TileQ", env, seed=seed, **kwargs)
    callback = Checkpoints(
        settings["checkpoint"],
        settings["gain_at"] if variant in GAIN_VARIANTS else (),
        settings["steps"],
        settings["env_id"],
        settings.get("eval_episodes", 0),
        seed,
    )
    diverged = False
    try:
        model.learn(settings["steps"], callback=callback)
    except DivergenceError:
        diverged = True
    frame = pd.DataFrame(callback.rows)
    frame["diverged"] = diverged
    wall = time.perf_counter() - start
    record = records.normalized(
        {
            "format": records.RECORD_FORMAT,
            "run": f"{problem}/{variant}/seed_{seed}",
            **code,
            "config": {
                "problem": problem,
                "variant": variant,
                "algorithm": algo,
                "env_id": settings["env_id"],
                "env_kwargs": env_kwargs,
                "algorithm_kwargs": kwargs,
                "seed": seed,
                "steps": settings["steps"],
                "checkpoint": settings["checkpoint"],
                "gain_at": list(settings["gain_at"]) if variant in GAIN_VARIANTS else [],
            },
            "resolved": records.resolved_settings(model, env),
            "dependencies": records.dependency_versions(),
            "python": platform.python_version(),
            "host": socket.gethostname(),
            "finished_at": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            "wall_time_s": wall,
        }
    )
    csv.parent.mkdir(parents=True, exist_ok=True)
    records.write_json_atomically(records.record_path(csv), record)
    partial = csv.with_name(csv.name + ".partial")
    frame.to_csv(partial, index=False)
    partial.replace(csv)
    env.close()
    print(f"{problem} {variant} seed {seed}: {wall:.0f} s, largest Q(s,a) {frame['max_q_sa'].iloc[-1]:.4g}", flush=True)
    return csv


# --- Figure 5.6 ----------------------------------------------------------------------------------------------------

FIGURE_REPLAYS = 400


def figure_5_6(out: Path) -> tuple[list[Path], list[str]]:
    """Figure 5.6 per case: Q(s_k, a_k) over replays for the four variants (kernels) with the closed form; the limit
    against the shared tiles; the markdown table of the limits."""
    figure, axes = plt.subplots(1, 2, figsize=(10.0, 4.0))
    lines = [
        "| Case | Variant | Q(s_k, a_k) after 1 / 10 / 100 / 400 replays (kernels) | limit (closed form) | "
        "max deviation kernels vs closed form |",
        "|---|---|---|---|---|",
    ]
    for axis, case in zip(axes, vg.CASES, strict=True):
        values = vg.CASES[case]
        for variant in vg.VARIANTS:
            got = vg.replay_values(vg.self_affecting_model(variant, case), FIGURE_REPLAYS)
            want = vg.closed_form(variant, case, FIGURE_REPLAYS)
            (line,) = axis.plot(got, label=variant)
            axis.plot(want, linestyle=":", color="black", linewidth=0.8)
            deviation = float(np.max(np.abs(got - want)))
            lines.append(
                f"| {case} | {variant} | {got[1]:.3f} / {got[10]:.2f} / {got[100]:.1f} / {got[-1]:.1f} | "
                f"{vg.limit_value(variant, case):.2f} | {deviation:.1e} |"
            )
        target = values["reward"] + vg.FIGURE_GAMMA * values["q_next"]
        axis.axhline(target, color="grey", linestyle="--", linewidth=0.8, label=f"initial target {target:g}")
        axis.axhline(0.0, color="grey", linewidth=0.5)
        axis.set_title(
            f"({case}) r = {values['reward']:g}, Q(s,a)₀ = {values['q_state']:g}, Q(s',a)₀ = {values['q_next']:g}",
            fontsize="small",
        )
        axis.set_xlabel("replays of the sample")
        axis.set_ylabel("Q(s_k, a_k)")
        axis.set_yscale("symlog", linthresh=10.0)
        axis.grid(alpha=0.3)
    axes[0].legend(fontsize="small")
    figure.suptitle(
        "Figure 5.6: a self-affecting sample, 4 tilings, s' shares 3 (γ 0.98, α 0.25); dotted: closed form",
        fontsize="medium",
    )
    figure.tight_layout()
    first = out / "figure_5_6.png"
    figure.savefig(first, dpi=120)
    plt.close(figure)

    figure, axes = plt.subplots(1, 2, figsize=(10.0, 4.0))
    n_tilings = 16
    shared = np.arange(1, n_tilings)
    for axis, case in zip(axes, vg.CASES, strict=True):
        for variant in vg.VARIANTS:
            axis.plot(
                shared, [vg.limit_value(variant, case, n_tilings, int(k)) for k in shared], marker=".", label=variant
            )
        axis.set_title(f"case ({case}): limit of Q(s_k, a_k), 16 tilings", fontsize="small")
        axis.set_xlabel("tiles of s_k shared by s_{k+1}")
        axis.set_yscale("symlog", linthresh=10.0)
        axis.axhline(0.0, color="grey", linewidth=0.5)
        axis.grid(alpha=0.3)
    axes[0].legend(fontsize="small")
    figure.tight_layout()
    second = out / "limit_vs_shared_tiles.png"
    figure.savefig(second, dpi=120)
    plt.close(figure)
    return [first, second], lines


# --- Summary -------------------------------------------------------------------------------------------------------


def load_runs(out: Path) -> dict[tuple[str, str], dict[int, pd.DataFrame]]:
    runs: dict[tuple[str, str], dict[int, pd.DataFrame]] = {}
    for csv in sorted((out / "runs").glob("*/*/seed_*.csv")):
        problem, variant = csv.parent.parent.name, csv.parent.name
        runs.setdefault((problem, variant), {})[int(csv.stem.split("_")[1])] = pd.read_csv(csv)
    return runs


def values_figure(out: Path, problem: str, runs) -> Path:
    greedy = bool(PROBLEMS[problem].get("eval_episodes"))
    figure, axes = plt.subplots(1, 3 if greedy else 2, figsize=(16.0 if greedy else 11.0, 4.2))
    present = [variant for variant in VARIANTS if runs.get((problem, variant))]
    for variant in present:
        seeds = runs[(problem, variant)]
        for i, frame in enumerate(seeds.values()):
            kwargs = {"label": variant} if i == 0 else {}
            color = f"C{present.index(variant) % 10}"
            axes[0].plot(frame["timesteps"], frame["max_q_sa"], color=color, alpha=0.8, **kwargs)
            axes[1].plot(frame["timesteps"], frame["mean_excess_sigma_relative"] * 100, color=color, alpha=0.8)
            if greedy:
                axes[2].plot(frame["timesteps"], frame["greedy_median"], color=color, alpha=0.8)
    if greedy:
        axes[2].axhline(PROBLEMS[problem]["level"], color="black", linestyle="--", linewidth=0.8, label="target")
        axes[2].set_ylabel("median greedy return")
        axes[2].legend(fontsize="x-small")
    bound = PROBLEMS[problem]["reward_max"]
    gamma = PROBLEMS[problem]["gamma"]
    axes[0].axhline(
        max(bound / (1 - gamma), 0.0), color="black", linestyle="--", linewidth=0.8, label="largest possible return"
    )
    axes[0].set_yscale("symlog", linthresh=10.0)
    axes[0].set_ylim(-10.0, 1e8)  # runs that diverge further leave the top of the plot
    axes[0].set_ylabel("largest Q(s_t, a_t) over the stored transitions (cut at 10⁸)")
    axes[1].axhline(0.0, color="grey", linewidth=0.5)
    axes[1].axhline((1 - gamma) * 100, color="black", linestyle="--", linewidth=0.8, label="1 - γ")
    axes[1].set_ylabel("mean (T_σ - Q(s,a)) / mean |Q(s,a)|  [%]")
    for axis in axes:
        axis.set_xlabel("steps")
        axis.grid(alpha=0.3)
    axes[0].legend(fontsize="x-small")
    axes[1].legend(fontsize="x-small")
    figure.suptitle(f"{problem}: each line one seed", fontsize="medium")
    figure.tight_layout()
    path = out / f"{problem}_values.png"
    figure.savefig(path, dpi=120)
    plt.close(figure)
    return path


def _per_seed(values, form: str) -> str:
    return ", ".join(format(value, form) for value in values)


def run_table(problem: str, runs) -> list[str]:
    """One row per variant: figures of the last checkpoint, per seed where they differ much between seeds."""
    steps = PROBLEMS[problem]["steps"]
    lines = [
        f"| Variant (what it changes) | largest Q(s,a) at {steps:,} steps (at any checkpoint) | mean max_a "
        "Q(s',a) (highest at any checkpoint) | σ raises / "
        "lowers targets | mean T_σ - T_vanilla / mean abs Q | s' without a visited action (all checkpoints) | "
        "tiles of φ(s,a) in σ's φ(s',a') | replay updates per phase | stored tiles sharing a slot |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for variant, (_, _, _, what) in VARIANTS.items():
        seeds = runs.get((problem, variant))
        if not seeds:
            continue
        last = pd.DataFrame([frame.iloc[-1] for frame in seeds.values()])
        every = pd.concat(list(seeds.values()))
        no_visit = int(round((every["share_no_action_visited"] * every["transitions"]).sum()))
        diverged = " (diverged)" if last["diverged"].any() else ""
        collisions = (
            (_per_seed(last["collision_rate"] * 100, ".2f") + " %")
            if "collision_rate" in last and last["collision_rate"].notna().all()
            else "-"
        )
        lines.append(
            f"| {variant} ({what}) | {_per_seed(last['max_q_sa'], '.4g')}{diverged} "
            f"({_per_seed([frame['max_q_sa'].max() for frame in seeds.values()], '.4g')}) | "
            f"{_per_seed(last['mean_max_q_next'], '.4g')} "
            f"({_per_seed([frame['mean_max_q_next'].max() for frame in seeds.values()], '.4g')}) | "
            f"{_per_seed(last['share_raised'] * 100, '.1f')} % / "
            f"{_per_seed(last['share_lowered'] * 100, '.1f')} % | "
            f"{_per_seed(last['mean_shift_relative'] * 100, '+.2f')} % "
            f"| {no_visit} of {int(every['transitions'].sum()):,} | "
            f"{_per_seed(last['mean_overlap_sigma'] * 100, '.1f')} % "
            f"| {_per_seed(last['replay_updates'] / last['replay_phases'], ',.0f')} | {collisions} |"
        )
    return lines


def greedy_table(problem: str, runs) -> list[str]:
    """One row per variant of a problem with greedy checkpoints: the greedy medians over learning and at the end, the
    seeds at the problem's level, the largest stored Q at the end and the values the watch saw outside the returns."""
    settings = PROBLEMS[problem]
    level = settings["level"]
    lines = [
        f"| Variant (what it changes) | greedy median at {settings['steps']:,} steps, per seed | seeds at "
        f"{level:g} | worst greedy median after {2 * settings['checkpoint']:,} steps, per seed | largest Q(s,a) "
        "at the end, per seed | first checkpoint with a stored Q(s,a) > 0, per seed | values outside the "
        "possible returns (watch), per seed |",
        "|---|---|---:|---|---|---|---|",
    ]
    for variant, (_, _, _, what) in VARIANTS.items():
        seeds = runs.get((problem, variant))
        if not seeds:
            continue
        frames = [seeds[seed] for seed in sorted(seeds)]
        final = [frame["greedy_median"].iloc[-1] for frame in frames]
        worst = [frame.loc[frame["timesteps"] >= 2 * settings["checkpoint"], "greedy_median"].min() for frame in frames]
        positive = [frame.loc[frame["max_q_sa"] > 0, "timesteps"] for frame in frames]
        first = ", ".join(f"{int(p.iloc[0]):,}" if len(p) else "never" for p in positive)
        lines.append(
            f"| {variant} ({what}) | {_per_seed(final, '.1f')} | {sum(f >= level for f in final)}/"
            f"{len(final)} | {_per_seed(worst, '.1f')} | {_per_seed([f['max_q_sa'].iloc[-1] for f in frames], '.3g')} "
            f"| {first} | {_per_seed([int(f['values_out_of_range'].iloc[-1]) for f in frames], ',d')} |"
        )
    return lines


def gain_column(sigma) -> str:
    return f"gain_{sigma or 'vanilla'}"


def gain_table(problem: str, runs) -> list[str]:
    lines = [
        "| Variant run | at steps | " + " | ".join(f"gain, {s or 'vanilla'}" for s in SIGMAS_FOR_GAIN) + " |",
        "|---|---|" + "---|" * len(SIGMAS_FOR_GAIN),
    ]
    for variant in GAIN_VARIANTS:
        for seed, frame in sorted(runs.get((problem, variant), {}).items()):
            for _, row in frame.dropna(subset=["gain_vanilla"]).iterrows():
                lines.append(
                    f"| {variant} seed {seed} | {int(row['timesteps']):,} | "
                    + " | ".join(f"{row[gain_column(s)]:.4f}" for s in SIGMAS_FOR_GAIN)
                    + " |"
                )
    return lines


def write_summary(out: Path, figure_lines: list[str], figures: list[Path], command: str) -> Path:
    runs = load_runs(out)
    sections = [
        "# The value-growth mechanism, measured",
        "",
        f"Regenerate: `{command}` (resumable; the figure part takes seconds). The page explaining these "
        "figures is `docs/value_growth.md`.",
        "",
    ]
    if figure_lines:
        sections += [
            "## Figure 5.6: one self-affecting sample",
            "",
            "One stored transition whose s' shares 3 of the 4 tiles of s, replayed alone through "
            "`model.replay` (the kernels); the closed form of `sb3_er.experiments.value_growth.closed_form` "
            "beside it.",
            "",
            "<!-- figure-start -->",
            "",
            *figure_lines,
            "",
            "<!-- figure-end -->",
            "",
            "Figures: `figure_5_6.png`, `limit_vs_shared_tiles.png`.",
            "",
        ]
    for problem in PROBLEMS:
        if not any(key[0] == problem for key in runs):
            continue
        figures.append(values_figure(out, problem, runs))
        settings = PROBLEMS[problem]
        sections += [
            f"## {problem} ({settings['env_id']}, {settings['steps']:,} steps per run, "
            f"{settings.get('reading', 'the env' + chr(39) + 's default reading')})",
            "",
            *(
                [
                    "Greedy policy (median of "
                    f"{settings['eval_episodes']} greedy episodes at each checkpoint, env reset with seed "
                    "1000 + seed) beside the values:",
                    "",
                    f"<!-- {problem}-greedy-start -->",
                    "",
                    *greedy_table(problem, runs),
                    "",
                    f"<!-- {problem}-greedy-end -->",
                    "",
                ]
                if settings.get("eval_episodes")
                else []
            ),
            f"Instrumented every {settings['checkpoint']:,} steps on the stored transitions; the last "
            "checkpoint per run, one figure per seed:",
            "",
            f"<!-- {problem}-runs-start -->",
            "",
            *run_table(problem, runs),
            "",
            f"<!-- {problem}-runs-end -->",
            "",
            "Gain of the replay operator per replay phase with every reward set to 0 (the learned weights, "
            "the stored data, one phase as the run replays it; > 1: replay expands the values whatever the "
            "rewards):",
            "",
            f"<!-- {problem}-gain-start -->",
            "",
            *gain_table(problem, runs),
            "",
            f"<!-- {problem}-gain-end -->",
            "",
            f"Figure: `{problem}_values.png`.",
            "",
        ]
    all_records = [records.read_record(csv) for csv in sorted((out / "runs").glob("*/*/seed_*.csv"))]
    if all_records:
        sections += [records.code_versions_line(all_records), ""]
    path = out / "summary.md"
    partial = path.with_name("summary.md.partial")
    partial.write_text("\n".join(sections) + "\n")
    partial.replace(path)
    return path


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--parts", nargs="*", default=list(DEFAULT_PARTS), choices=["figure", *PROBLEMS])
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--variants", nargs="*", default=list(VARIANTS), choices=list(VARIANTS))
    parser.add_argument("--out", default=str(OUT))
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    import torch

    torch.set_num_threads(1)
    figures, figure_lines = (
        figure_5_6(out) if "figure" in args.parts or (out / "figure_5_6.png").is_file() else ([], [])
    )
    for problem in PROBLEMS:
        if problem in args.parts:
            for seed in range(args.seeds):
                for variant in args.variants:
                    if applies(problem, variant):
                        run(problem, variant, seed, out)
    command = "python " + " ".join(["benchmarks/value_growth/run.py", *(sys.argv[1:] if argv is None else argv)])
    print(write_summary(out, figure_lines, figures, command.strip()))


if __name__ == "__main__":
    main()
