"""Every task of dm_control's suite by id: the ones a model can act on learn, save, load and predict; the others are
refused with the error that says what to give.

    python benchmarks/dmc_suite.py [--tasks cartpole-balance reacher-easy ...] [--algo er_sigma] [--steps 1000]
        [--out results/measured/dmc_suite]

For each task of ``dm_control.suite.ALL_TASKS`` (or ``--tasks``), the expectation comes from the task's action spec
alone, read from dm_control and MuJoCo, not from sb3-er:

- up to 3 action dimensions, each with a control range: ``Algo("TileQ", "dm_control/<domain>-<task>-v0", seed=0)``
  builds with nothing else given, learns ``--steps`` steps, saves, loads with the id as its env and predicts the same
  greedy action as before saving, of the Box's shape and inside its bounds;
- more than 3 action dimensions: a ValueError naming ``action_bins`` (the default 7 levels stop at 7^3 joint
  actions), before any rollout;
- an actuator without a control range (MuJoCo reports ``mjMAXVAL`` as its bound: lqr's motors): a ValueError naming
  ``action_values``; the task then learns with explicit levels (-1, 0, 1 per dimension), shown as a second row.

Each row says where the tiling came from (the id's shipped tiling, its domain's, or derived from a rollout), the
values the learner may take and how many the value watch saw outside them, and the seconds the row took; the last
lines count the outcomes and the whole sweep's time. The table is printed as it grows and written to
``<out>/summary.md`` at the end. The exit status is 1 when any task does not do what its action spec says.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

from sb3_er import ValueBoundWarning  # noqa: E402
from sb3_er.common.atomic import write_atomically  # noqa: E402
from sb3_er.common.dict_observations import register_dm_control_envs  # noqa: E402
from sb3_er.common.dm_control_tilings import DerivedTilingWarning  # noqa: E402
from sb3_er.zoo import algorithm_classes  # noqa: E402

#: The most action dimensions the default levels cover (7 levels each, 7^3 joint actions).
MAX_DEFAULT_ACTION_DIMS = 3


def action_spec(task: str):
    """dm_control's own action spec of ``domain-task``."""
    from dm_control import suite

    domain, _, name = task.partition("-")
    return suite.load(domain, name).action_spec()


def expectation(spec) -> str:
    """``learns``, ``action_bins`` or ``action_values``, from a task's action spec (dm_control's own, with MuJoCo's
    bound for an actuator without a control range)."""
    import mujoco

    if int(np.prod(spec.shape)) > MAX_DEFAULT_ACTION_DIMS:
        return "action_bins"
    unlimited = np.any(np.abs(spec.minimum) >= mujoco.mjMAXVAL) or np.any(np.abs(spec.maximum) >= mujoco.mjMAXVAL)
    return "action_values" if unlimited else "learns"


def tiling_origin(model, caught: list[warnings.WarningMessage], env_id: str) -> str:
    if any(issubclass(w.category, DerivedTilingWarning) for w in caught):
        return "derived"
    from sb3_er.common.tile_coding import package_tilings

    entry = package_tilings().get(env_id)
    widths = [float(w) for w in model.policy.tile_coder.tile_widths]
    if entry is not None:
        return "own" if np.allclose(widths, entry["tile_widths"]) else "other"
    return "domain"


def run(env_id: str, algo: str, steps: int, policy_kwargs: dict | None = None) -> tuple[str, str]:
    """(outcome, detail): ``learns`` and the tiling's origin, or the refusal's kind and its message."""
    cls = algorithm_classes()[algo]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            model = cls("TileQ", env_id, seed=0, policy_kwargs=policy_kwargs)
        except ValueError as error:
            message = str(error)
            kind = "action_bins" if "action_bins" in message else "action_values" if "action_values" in message else ""
            rollout = any(issubclass(w.category, DerivedTilingWarning) for w in caught)
            return (kind or "other error") + (" after a rollout" if rollout else ""), message.split(". ")[0]
        origin = tiling_origin(model, caught, env_id)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ValueBoundWarning)  # counted below (values_out_of_range)
        model.learn(steps)
    observation, _ = gym.wrappers.FlattenObservation(gym.make(env_id)).reset(seed=1)
    action, _ = model.predict(observation, deterministic=True)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "model.zip"
        model.save(path)
        loaded = cls.load(path, env=env_id)
    again, _ = loaded.predict(observation, deterministic=True)
    box = model.action_space
    problems = []
    if model.num_timesteps != steps:
        problems.append(f"learned {model.num_timesteps} steps")
    if action.shape != box.shape or not box.contains(action.astype(box.dtype)):
        problems.append(f"action {action} outside {box}")
    if not np.array_equal(action, again) or not np.array_equal(loaded.policy.theta_array, model.policy.theta_array):
        problems.append("the loaded model differs")
    bounds = model.value_bounds
    detail = (
        f"tiling {origin}, {model.policy.tile_coder.n_dims} dims; possible values [{bounds[0]:.4g}, {bounds[1]:.4g}], "
        f"{model.values_out_of_range} outside"
    )
    return ("learns" if not problems else "broken"), detail + ("; " + "; ".join(problems) if problems else "")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", nargs="+", default=None, help="domain-task names (default: suite.ALL_TASKS)")
    parser.add_argument("--algo", default="er_sigma", choices=sorted(algorithm_classes()))
    parser.add_argument("--steps", type=int, default=1_000)
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parents[1] / "results/measured/dmc_suite")
    args = parser.parse_args(argv)
    register_dm_control_envs()
    from dm_control import suite

    tasks = [f"{d}-{t}" for d, t in suite.ALL_TASKS] if args.tasks is None else args.tasks
    from importlib.metadata import version

    versions = ", ".join(f"{name} {version(name)}" for name in ("sb3-er", "dm-control", "mujoco", "shimmy"))
    lines: list[str] = []

    def emit(line: str = "") -> None:
        lines.append(line)
        print(line, flush=True)

    emit(f"## dm_control's suite by id: {args.algo}, {args.steps} steps, {len(tasks)} tasks\n")
    emit(f"`python benchmarks/dmc_suite.py --algo {args.algo} --steps {args.steps}`; {versions}.\n")
    emit("| task | action dims | expected | outcome | detail | s |")
    emit("|---|---:|---|---|---|---:|")
    start = time.perf_counter()
    counts: dict[str, int] = {}
    mismatches = []
    for task in tasks:
        env_id = f"dm_control/{task}-v0"
        began = time.perf_counter()
        spec = action_spec(task)
        expected, dims = expectation(spec), int(np.prod(spec.shape))
        outcome, detail = run(env_id, args.algo, args.steps)
        rows = [(task, expected, outcome, detail, time.perf_counter() - began)]
        if expected == "action_values" and outcome == "action_values":
            began = time.perf_counter()
            levels = dict(action_values=[[-1.0, 0.0, 1.0]] * dims)
            outcome_levels, detail_levels = run(env_id, args.algo, args.steps, levels)
            name = f"{task} with action_values -1, 0, 1"
            rows.append((name, "learns", outcome_levels, detail_levels, time.perf_counter() - began))
        for name, want, got, text, seconds in rows:
            counts[got] = counts.get(got, 0) + 1
            if want != got:
                mismatches.append(name)
            emit(f"| {name} | {dims} | {want} | {got} | {text.replace('|', '/')} | {seconds:.1f} |")
    total = time.perf_counter() - start
    emit()
    emit(f"{len(tasks)} tasks in {total:.0f} s: " + ", ".join(f"{n} {k}" for k, n in sorted(counts.items())))
    emit(f"mismatches with the action specs: {mismatches or 'none'}")
    args.out.mkdir(parents=True, exist_ok=True)
    write_atomically(args.out / "summary.md", "\n".join(lines) + "\n")
    return 1 if mismatches else 0


if __name__ == "__main__":
    sys.exit(main())
