"""Thesis Figure 5.5 (section 5.2.2): pessimistic initialisation against ER-sigma on the same data and replays.

Per seed (one run of the runner, :func:`pessimistic_run`) and per case of the value-map study (tabular: one tiling of
width 1; tile coding: 16 tilings of width 2, see :data:`sb3_er.experiments.gridworld.CASES`):

1. A vanilla-ER learning run on the windy cliff is stopped just after it first collects a positive goal payout, as
   for Figures 5.2-5.7 (:func:`~sb3_er.experiments.gridworld.learn_until_goal`); its trajectories are the data.
2. Three fresh models replay that data with the same trajectory picks and the same exploration draws
   (:func:`~sb3_er.experiments.gridworld.replay_model`): vanilla ER and ER-sigma from zero weights (the thesis's
   setting) and vanilla ER whose Q starts at the pessimistic value everywhere (``initial_value``, default
   :data:`~sb3_er.experiments.gridworld.PESSIMISTIC_VALUE` = -50). Each does ``budget`` replay phases (default 30) of
   10 x the stored trajectories; the first phase is the situation of Table 5.1 and Figure 5.5, the last the long
   replay of Table 5.2.
3. Before the first phase (phase 0) and after every phase, the value map V(s) = max_a Q(s, a) of the 63 non-goal
   cells is summarised: how many cells have V > 0 (the goal's reward has reached them), below the wind and in it, and
   the statistics of the value-map study (windy max and mean, calm max and min), plus the smallest and largest Q over
   every (cell, action) (at phase 0 both equal the initial value).

Why -50: every reward of the grid world is -1 per step, -50 at the cliff or 0..50 at the goal. With gamma 0.98 a path
of k steps that ends in the cliff returns -(1 - gamma^k)/(1 - gamma) - 50 gamma^k = -50 exactly, and every other path
returns more. So -50 is the value of a certain fall and a lower bound of every true Q: Q starting there is as
pessimistic as the task allows while staying a possible value, and any positive value must come from the goal.

The thesis's claim: pessimistic initialisation back-propagates the goal's reward more slowly and more narrowly than
ER-sigma ("only through actual visited trajectories"): fewer cells with positive values. The figures of the first seed
show the maps (Figure 5.5); the table gives the positive cells per variant over all seeds.
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from sb3_er.common.env_ids import check_env_kwargs
from sb3_er.experiments import files
from sb3_er.experiments.analyses import check_request, check_settings, code_line, env_reading, run_analysis_jobs
from sb3_er.experiments.metrics import mean_confidence_interval
from sb3_er.experiments.records import counted
from sb3_er.experiments.runner import RunJob, TaskOutput, artifact_path, read_run_csv, run_csv_path
from sb3_er.experiments.specs import ANALYSES, Analysis

RUN_FOLDER = "pessimistic"
VARIANTS = ("er", "er_sigma", "er_pessimistic")
MAPS_ARTIFACT = "value_maps.csv"
SITUATIONS = {"after_goal": "after one replay phase (Table 5.1, Figure 5.5)", "long_replay": "after the long replay"}
THESIS_CLAIM = "slower, narrower back-propagation than ER-σ (fewer cells with V > 0)"


def variant_label(variant: str, initial_value: float) -> str:
    """Display name of a replay variant, the pessimistic one with its initial value.

    :param variant: the variant's name.
    :param initial_value: the pessimistic initial Q.
    """
    return {"er": "vanilla-ER", "er_sigma": "ER-σ"}.get(variant, f"ER, pessimistic Q₀ = {initial_value:g}")


def figure_variants(initial_value: float) -> dict[str, tuple[str, dict]]:
    """The variants of Figure 5.5: name -> (algorithm, policy kwargs on top of the case's tiling).

    :param initial_value: the pessimistic initial Q.
    """
    from sb3_er.experiments.gridworld import PESSIMISTIC, replay_variants

    variants = replay_variants(initial_value)
    return {name: variants[name] for name in ("er", "er_sigma", PESSIMISTIC)}


def _q_range(model, env) -> tuple[float, float]:
    """(min, max) of Q over every non-goal cell and action."""
    unwrapped = env.unwrapped
    xs, ys = np.meshgrid(np.arange(unwrapped.goal_column), np.arange(unwrapped.height))
    q = model.policy.q_values(np.column_stack([xs.ravel(), ys.ravel()]).astype(np.float64))
    return float(q.min()), float(q.max())


def pessimistic_run(job: RunJob, env, report) -> TaskOutput:
    """One seed of Figure 5.5 (see the module docstring): for each case collect until the first positive goal, then
    replay the data with every variant for ``job.budget`` phases, summarising the value map after each phase.

    Returns one row per (case, variant, phase) with ``replayed_trajectories``, :func:`positive_cells`,
    :func:`map_statistics`, ``q_min``, ``q_max``, ``collector_episodes``, ``database_trajectories``,
    ``database_sha256`` and ``diverged``; the tile-coding case's collector is the run's model. A figure run also
    returns the value maps after the first and the last phase (``value_maps.csv``: case, variant, phase, y, x,
    value). RuntimeError when no collector reaches the goal within 1000 episodes.

    :param job: the run.
    :param env: the env the runner made for it.
    :param report: called with the run's finished fraction, for the progress bar.
    """
    from sb3_er import DivergenceError
    from sb3_er.experiments.gridworld import (
        CASES,
        REPLAYS_PER_TRAJECTORY,
        learn_until_goal,
        map_statistics,
        positive_cells,
        replay_model,
        value_map,
    )
    from sb3_er.experiments.replay_order import database_digest

    start = time.perf_counter()
    phases = int(job.budget)
    initial_value = float(job.experiment.setting("initial_value"))
    first_windy_row = env.unwrapped.first_windy_row
    rows, map_rows = [], []
    collector = None
    steps = len(CASES) * len(VARIANTS)
    with tempfile.TemporaryDirectory() as scratch:
        for case_index, (case, policy_kwargs) in enumerate(CASES.items()):
            collector, episodes = learn_until_goal("er", env, policy_kwargs, job.seed)
            buffer_path = Path(scratch) / f"buffer_{case_index}.pkl"
            collector.save_replay_buffer(buffer_path)
            n_trajectories = collector.replay_buffer.n_trajectories
            database = {
                "collector_episodes": episodes,
                "database_trajectories": n_trajectories,
                "database_sha256": database_digest(collector.replay_buffer),
            }
            for variant_index, (variant, (algo, extra)) in enumerate(figure_variants(initial_value).items()):
                model = replay_model(algo, env, {**policy_kwargs, **extra}, job.seed, buffer_path)
                diverged = False
                for phase in range(phases + 1):
                    if phase:
                        try:
                            model.replay(REPLAYS_PER_TRAJECTORY * n_trajectories)
                        except DivergenceError:
                            diverged = True
                    values = value_map(model, env)
                    q_min, q_max = _q_range(model, env)
                    rows.append(
                        {
                            "case": case,
                            "variant": variant,
                            "phase": phase,
                            "replayed_trajectories": phase * REPLAYS_PER_TRAJECTORY * n_trajectories,
                            **positive_cells(values, first_windy_row),
                            **map_statistics(values, first_windy_row),
                            "calm_mean": float(values[:first_windy_row].mean()),
                            "q_min": q_min,
                            "q_max": q_max,
                            **database,
                            "diverged": diverged,
                            "values_out_of_range": model.values_out_of_range,
                            "wall_time_s": time.perf_counter() - start,
                        }
                    )
                    if job.figure_run and phase in (1, phases):
                        map_rows += [
                            {"case": case, "variant": variant, "phase": phase, "y": y, "x": x, "value": value}
                            for (y, x), value in np.ndenumerate(values)
                        ]
                    if diverged:
                        break
                report((case_index * len(VARIANTS) + variant_index + 1) / steps)
    artifacts = {}
    if map_rows:
        artifacts[MAPS_ARTIFACT] = files.csv_bytes(pd.DataFrame(map_rows))
    return TaskOutput(pd.DataFrame(rows), collector, artifacts)


def pessimistic_table(frames: dict[int, pd.DataFrame], phases: int, initial_value: float) -> pd.DataFrame:
    """Per (situation, case, variant): mean over seeds with 95% CI of the cells with V > 0 (all, calm, windy), the mean
    calm V, the windy max and the overall max of V (``max_v``), the paired difference of positive cells with ER-sigma
    (same data and replays), and the thesis's claim beside the pessimistic rows. Situations: after phase 1 and after
    phase `phases`.

    :param frames: the runs' CSVs by seed.
    :param phases: the long replay's phases.
    :param initial_value: the pessimistic initial Q.
    """
    data = pd.concat([frame.assign(seed=seed) for seed, frame in frames.items()], ignore_index=True)
    rows = []
    for situation, phase in (("after_goal", 1), ("long_replay", phases)):
        at = data[data["phase"] == phase]
        for case in dict.fromkeys(at["case"]):
            in_case = at[at["case"] == case]
            sigma = in_case[in_case["variant"] == "er_sigma"].set_index("seed")["positive_cells"]
            for variant in VARIANTS:
                values = in_case[(in_case["variant"] == variant) & ~in_case["diverged"].astype(bool)]
                row = {
                    "situation": situation,
                    "phase": phase,
                    "case": case,
                    "variant": variant,
                    "label": variant_label(variant, initial_value),
                    "seeds": len(values),
                }
                values = values.assign(max_v=np.maximum(values["calm_max"], values["windy_max"]))
                for column in (
                    "positive_cells",
                    "calm_positive_cells",
                    "windy_positive_cells",
                    "calm_mean",
                    "windy_max",
                    "max_v",
                ):
                    mean, half = mean_confidence_interval(values[column].to_numpy()) if len(values) else (math.nan,) * 2
                    row.update({column: float(mean), f"{column}_ci95": float(half)})
                differences = (values.set_index("seed")["positive_cells"] - sigma).dropna().to_numpy(dtype=float)
                mean, half = mean_confidence_interval(differences) if differences.size else (math.nan, math.nan)
                row.update(
                    {
                        "minus_er_sigma": float(mean),
                        "minus_er_sigma_ci95": float(half),
                        "fewer_than_er_sigma": int((differences < 0).sum()),
                        "thesis": THESIS_CLAIM if variant == "er_pessimistic" else "",
                    }
                )
                rows.append(row)
    return pd.DataFrame(rows)


def _format(value: float, half_width: float) -> str:
    if not math.isfinite(value):
        return "NA"
    return f"{value:.3g}" + (f" ± {half_width:.2g}" if math.isfinite(half_width) else "")


def _markdown(table: pd.DataFrame, phases: int) -> str:
    lines = [
        "| Situation | Case | Algorithm | Cells with V > 0 (of 63) | below the wind | in the wind | Calm mean V | "
        "Windy max V | Max V | − ER-σ (paired) | Thesis (Fig. 5.5) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in table.to_dict("records"):
        situation = "after 1 phase" if row["situation"] == "after_goal" else f"after {phases} phases"
        paired = (
            "—"
            if row["variant"] == "er_sigma"
            else (
                f"{_format(row['minus_er_sigma'], row['minus_er_sigma_ci95'])} "
                f"(fewer in {row['fewer_than_er_sigma']} of {row['seeds']})"
            )
        )
        lines.append(
            f"| {situation} | {row['case']} | {row['label']} | "
            f"{_format(row['positive_cells'], row['positive_cells_ci95'])} | "
            f"{_format(row['calm_positive_cells'], row['calm_positive_cells_ci95'])} | "
            f"{_format(row['windy_positive_cells'], row['windy_positive_cells_ci95'])} | "
            f"{_format(row['calm_mean'], row['calm_mean_ci95'])} | {_format(row['windy_max'], row['windy_max_ci95'])} "
            f"| {_format(row['max_v'], row['max_v_ci95'])} | {paired} | {row['thesis'] or '—'} |"
        )
    return "\n".join(lines)


def _verdict(table: pd.DataFrame, largest_value: float) -> str:
    """Our reading of the pessimistic rows against ER-sigma, flagging situations whose mean max V exceeds
    `largest_value` (the best goal payout: no true value is larger)."""
    pessimistic = table[table["variant"] == "er_pessimistic"]
    parts = []
    for row in pessimistic.itertuples():
        if not math.isfinite(row.minus_er_sigma):
            continue
        upper = row.minus_er_sigma + (row.minus_er_sigma_ci95 if math.isfinite(row.minus_er_sigma_ci95) else 0.0)
        if upper < 0:
            word = "fewer positive cells than ER-σ (CI below 0)"
        elif row.minus_er_sigma < 0:
            word = "fewer positive cells than ER-σ on average, the CI including 0"
        else:
            word = "no fewer positive cells than ER-σ"
        situation = "after 1 phase" if row.situation == "after_goal" else f"after {row.phase} phases"
        at = table[(table["situation"] == row.situation) & (table["case"] == row.case)]
        grown = [label for label, value in zip(at["label"], at["max_v"], strict=True) if value > largest_value]
        if grown:
            word += (
                f" (mean max V above {largest_value:g} for {', '.join(grown)}: approximation errors that grow "
                "in replay without new data, Table 5.2's local maxima, so here positive cells count those "
                "errors as much as the goal's reward)"
            )
        parts.append(f"{row.case}, {situation}: {word}")
    return "Ours, pessimistic ER against ER-σ: " + "; ".join(parts) + "." if parts else ""


@files.holds_folder_locks
def reproduce_pessimistic(
    n_seeds: int = 20,
    out_dir: str | Path | None = None,
    budget: float | None = None,
    n_workers: int | None = None,
    first_seed: int = 0,
    show_progress: bool = True,
    backend: str = "local",
    address: str | None = None,
    allow_mixed_versions: bool = False,
    env_kwargs: dict | None = None,
    initial_value: float | None = None,
):
    """`sb3-er reproduce pessimistic`: Figure 5.5 over `n_seeds` data sets (one run per seed on the runner).

    `budget` is the number of replay phases of the long replay (default 30), `initial_value` the pessimistic Q
    (default -50), `env_kwargs` a grid-world reading other than its defaults. Writes ``runs/pessimistic/seed_<n>.csv``
    (and ``.json``; the first seed also ``seed_<n>_value_maps.csv``), ``summary.md``, ``summary.csv``,
    ``value_maps_pessimistic_after_goal.png`` and ``value_maps_pessimistic_long_replay.png`` (the first seed's maps,
    Figure 5.5) and ``positive_cells.png`` (cells with V > 0 against replay phases, mean and 95 % CI per case) into
    `out_dir` (default ``results/pessimistic``). Returns a Reproduction. ValueError for bad settings or a folder
    holding runs of other settings; MixedVersionsError / RunFailure as :func:`sb3_er.experiments.reproduce.reproduce`.

    :param n_seeds: the number of seeds (default 20, the thesis's).
    :param out_dir: the results folder (default None: ``results/<name>``).
    :param budget: replay phases of the long replay (default None: 30).
    :param n_workers: worker processes, or the local Ray instance's CPUs (default None: all CPUs).
    :param first_seed: the first seed; the seeds are ``first_seed, ..., first_seed + n_seeds - 1`` (default 0).
    :param show_progress: show a progress bar (default True).
    :param backend: "local" (default) or "ray".
    :param address: the Ray cluster's address (default None: a new local instance; only with ``backend="ray"``).
    :param allow_mixed_versions: accept finished runs made by other code or settings (default False: refused).
    :param env_kwargs: ``gymnasium.make`` keyword arguments, a reading of the env other than its defaults (default
        None).
    :param initial_value: the pessimistic initial Q (default None: -50).
    """
    import gymnasium as gym
    import matplotlib.pyplot as plt

    import sb3_er_envs  # noqa: F401
    from sb3_er.experiments.plots import plot_value_maps
    from sb3_er.experiments.reproduce import Reproduction

    start = time.perf_counter()
    base: Analysis = ANALYSES["pessimistic"]
    budget = float(base.default_budget if budget is None else budget)
    check_request(n_seeds, budget, base.budget_unit, backend, address)
    if int(budget) != budget:
        raise ValueError(f"the long replay is a whole number of replay phases, got {budget}")
    initial_value = float(base.setting("initial_value") if initial_value is None else initial_value)
    if not math.isfinite(initial_value):
        raise ValueError(f"the pessimistic initial value must be finite, got {initial_value}")
    experiment = base.with_settings(initial_value=initial_value)
    env_kwargs = dict(env_kwargs or {})
    check_env_kwargs(experiment.env_id, env_kwargs)  # once, before any run: not one failure per run
    out_dir = Path(out_dir if out_dir is not None else Path("results") / experiment.name)
    settings = {
        "experiment": experiment.name,
        "env_id": experiment.env_id,
        "budget": budget,
        "initial_value": initial_value,
        "env_kwargs": env_kwargs,
    }
    files.lock_folder(out_dir)  # one writer per folder, until this function returns
    check_settings(out_dir, settings)
    seeds = list(range(first_seed, first_seed + n_seeds))
    jobs = [
        RunJob(
            experiment,
            "er",
            seed,
            budget,
            run_csv_path(out_dir, RUN_FOLDER, seed),
            tuple(sorted(env_kwargs.items())),
            figure_run=seed == first_seed,
            label=RUN_FOLDER,
        )
        for seed in seeds
    ]
    done, skipped = run_analysis_jobs(
        jobs, out_dir, n_workers, show_progress, backend, address, allow_mixed_versions, settings={out_dir: settings}
    )

    phases = int(budget)
    frames = {job.seed: read_run_csv(job.csv_path) for job in jobs if job.csv_path.is_file()}
    table = pessimistic_table(frames, phases, initial_value)
    table_csv = files.write_csv(out_dir / "summary.csv", table)
    figures = []
    maps_csv = artifact_path(jobs[0].csv_path, MAPS_ARTIFACT)
    grid = gym.make(experiment.env_id, **env_kwargs).unwrapped
    first_windy_row, largest_value = grid.first_windy_row, max(grid.goal_reward, 0.0)
    if maps_csv.is_file():
        maps = read_run_csv(maps_csv)
        for situation, phase in (("after_goal", 1), ("long_replay", phases)):
            cases = {}
            for case in dict.fromkeys(maps["case"]):
                cases[case] = {}
                for variant in VARIANTS:
                    cells = maps[(maps["case"] == case) & (maps["variant"] == variant) & (maps["phase"] == phase)]
                    if len(cells):
                        grid = np.full((cells["y"].max() + 1, cells["x"].max() + 1), np.nan)
                        grid[cells["y"], cells["x"]] = cells["value"]
                        cases[case][variant_label(variant, initial_value)] = grid
            title = (
                f"Windy cliff (seed {first_seed}), same data and replays, {SITUATIONS[situation]}: "
                f"pessimistic Q₀ = {initial_value:g}"
            )
            figures.append(
                plot_value_maps(cases, first_windy_row, title, out_dir / f"value_maps_pessimistic_{situation}.png")
            )
    figures.append(_plot_positive_cells(frames, initial_value, out_dir / "positive_cells.png", plt))
    sections = [
        f"# {experiment.title}: {counted(len(frames), 'seed')}, "
        f"pessimistic Q₀ = {initial_value:g}, {phases} replay phases",
        "",
        "Per seed and case: the data of a vanilla-ER run stopped after its first positive goal payout, replayed by "
        "vanilla ER and ER-σ from zero weights and by vanilla ER from Q₀ everywhere, with the same trajectory picks "
        "and exploration draws; a phase replays 10 × the stored trajectories. Cells: the 63 non-goal cells of "
        "V = max_a Q; mean over seeds ± 95 % CI. The paired column is the variant's positive cells minus ER-σ's on the "
        f"same data. No true value exceeds {largest_value:g} (the best goal payout), so a larger max V is an "
        "approximation error.",
        "",
        _markdown(table, phases),
        "",
        "Thesis (section 5.2.2, Figure 5.5, no numbers): pessimistic initialisation back-propagates the goal's reward "
        "more slowly and narrowly than ER-σ, only through actually visited trajectories.",
        "",
        _verdict(table, largest_value),
        "",
        f"Why Q₀ = {initial_value:g}: with γ 0.98 every path that ends in the cliff returns exactly -50 "
        "(-(1 − γᵏ)/(1 − γ) − 50 γᵏ), every other path more: -50 is the cliff's reward, the value of a certain fall "
        "and the lowest true Q, so a Q starting there is as pessimistic as the task allows and only the goal lifts it.",
        "",
        f"Grid-world reading (env arguments at run time): {env_reading(jobs)}.",
        "",
        code_line(jobs),
    ]
    table_markdown = files.write_atomically(out_dir / "summary.md", "\n".join(sections) + "\n")
    return Reproduction(
        out_dir=out_dir,
        table_markdown=table_markdown,
        table_csv=table_csv,
        figures=figures,
        runs_done=done,
        runs_skipped=skipped,
        wall_time_s=time.perf_counter() - start,
    )


def _plot_positive_cells(frames: dict[int, pd.DataFrame], initial_value: float, path: Path, plt) -> Path:
    """Cells with V > 0 against replay phases, one panel per case, mean over seeds with a 95% CI band per variant."""
    data = pd.concat([frame.assign(seed=seed) for seed, frame in frames.items()], ignore_index=True)
    cases = list(dict.fromkeys(data["case"]))
    figure, axes = plt.subplots(1, len(cases), figsize=(5.0 * len(cases), 3.8), squeeze=False)
    for panel, case in zip(axes[0], cases, strict=True):
        for variant in VARIANTS:
            wide = (
                data[(data["case"] == case) & (data["variant"] == variant)]
                .pivot_table(index="seed", columns="phase", values="positive_cells")
                .dropna()
            )
            if wide.empty:
                continue
            mean, half = mean_confidence_interval(wide.to_numpy())
            x = wide.columns.to_numpy(dtype=float)
            (line,) = panel.plot(x, mean, label=f"{variant_label(variant, initial_value)} (n={len(wide)})")
            if np.isfinite(half).any():
                panel.fill_between(x, mean - half, mean + half, color=line.get_color(), alpha=0.2, linewidth=0)
        panel.set_title(case, fontsize="small")
        panel.set_xlabel("replay phases (10 × the stored trajectories each)")
        panel.set_ylabel("cells with V > 0 (of 63)")
        panel.grid(alpha=0.3)
        panel.legend(fontsize="small")
    figure.suptitle(
        f"Windy cliff: spread of the goal's reward on the same data and replays "
        f"(pessimistic Q₀ = {initial_value:g}), mean of {counted(len(frames), 'seed')}, 95% CI",
        fontsize="medium",
    )
    figure.tight_layout()
    files.save_figure(figure, path, dpi=120)
    plt.close(figure)
    return path
