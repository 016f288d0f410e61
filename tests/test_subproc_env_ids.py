"""Env ids made in SubprocVecEnv workers: dm_control's suite, the package's own sb3_er/ ids and LEO, registered by
the parent process inside its main function (not at the top of the script, where a forkserver would import it), and
`sb3-er train --vec-env subproc`.

Each case runs in a fresh interpreter, as a user's script does: a forkserver started by an earlier test of this
process would not import the modules registered afterwards. Those runs take tens of seconds (each interpreter
imports torch, dm_control and MuJoCo); the fast test checks what they rely on: registering names the module that
registers again in the forkserver."""

import importlib.util
import json
import subprocess
import sys

import numpy as np
import pytest

from sb3_er.common.tile_coding import package_tilings

needs_dmc = pytest.mark.skipif(
    importlib.util.find_spec("shimmy") is None or importlib.util.find_spec("dm_control") is None,
    reason="the dm_control ids and LEO need the dmc extra",
)

SCRIPT = """
import json, sys

def main():
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv
    from sb3_er import SarsaLambda
{register}
    results = {{}}
    for env_id, wrapper in {ids!r}:
        wrapper_class = None
        if wrapper:
            from sb3_er.common.dict_observations import FlattenSuiteObservation as wrapper_class
        vec = make_vec_env(env_id, n_envs=1, vec_env_cls=SubprocVecEnv, wrapper_class=wrapper_class, seed=0)
        assert type(vec) is SubprocVecEnv
        model = SarsaLambda("TileQ", vec, seed=0, policy_kwargs=dict(n_tilings=2, memory_size=2**12))
        model.learn(300)
        results[env_id] = dict(
            steps=model.num_timesteps,
            widths=[float(w) for w in model.policy.tile_coder.tile_widths],
            watch=model._watch.source,
            bounds=list(model.value_bounds),
            spec_id=vec.get_attr("spec")[0].id,
        )
        vec.close()
    print(json.dumps(results))

if __name__ == "__main__":
    main()
"""


def test_registering_an_id_names_its_registering_module_for_the_forkserver():
    from multiprocessing import forkserver

    from sb3_er.common.env_ids import register_env_id

    register_env_id("sb3_er/PendulumSwingup-v0")
    assert "sb3_er_envs" in forkserver._forkserver._preload_modules
    assert forkserver._forkserver._preload_modules[0] == "__main__"  # the main script still comes first
    if importlib.util.find_spec("shimmy") is not None and importlib.util.find_spec("dm_control") is not None:
        register_env_id("dm_control/pendulum-swingup-v0")
        assert "sb3_er.common.register_dm_control" in forkserver._forkserver._preload_modules


def run_script(register: str, ids: list[tuple[str, bool]]) -> dict:
    code = SCRIPT.format(register=register, ids=ids)
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-4000:]
    return json.loads(result.stdout.strip().splitlines()[-1])


@needs_dmc
@pytest.mark.slow
def test_a_dm_control_id_learns_in_a_subprocess_worker():
    """Before: the worker knew no dm_control/ id, and once it did, it died sending shimmy's spec (a local function
    cannot be pickled) when the model asked for it, which the VecEnv reported as a bare EOFError."""
    env_id = "dm_control/pendulum-swingup-v0"
    register = (
        "    from sb3_er.common.dict_observations import register_dm_control_envs\n    register_dm_control_envs()"
    )
    result = run_script(register, [(env_id, True)])[env_id]
    assert result["steps"] == 300 and result["spec_id"] == env_id
    np.testing.assert_allclose(result["widths"], package_tilings()[env_id]["tile_widths"])  # found by the id
    # the suite's reward bounds reach the watch from the worker: [0, 1] a step, returns in [0, 1 / (1 - 0.99)]
    assert result["watch"] == "env" and result["bounds"] == pytest.approx([0.0, 100.0])


@needs_dmc
@pytest.mark.slow
def test_the_packages_ids_and_leo_learn_in_a_subprocess_worker():
    ids = ["sb3_er/PendulumSwingup-v0", "sb3_er/Leo-v0"]
    result = run_script("    import sb3_er_envs", [(env_id, False) for env_id in ids])
    for env_id in ids:
        assert result[env_id]["steps"] == 300 and result[env_id]["spec_id"] == env_id
        assert result[env_id]["watch"] == "env"  # each declares its reward_bounds


@needs_dmc
@pytest.mark.slow
def test_sb3_er_train_with_subprocess_envs_on_a_dm_control_id(tmp_path):
    """rl-zoo's --vec-env subproc, 300 steps; the zoo entry's FlattenSuiteObservation flattens each worker's Dict."""
    env_id = "dm_control/pendulum-swingup-v0"
    command = [sys.executable, "-m", "sb3_er.zoo", "train", "--algo", "sarsa_lambda", "--env", env_id, "-n", "300"]
    command += ["-f", str(tmp_path), "--seed", "0", "--eval-freq", "-1", "--vec-env", "subproc", "--verbose", "0"]
    result = subprocess.run(command, capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, result.stderr[-4000:]
    from sb3_er import SarsaLambda

    run = tmp_path / "sarsa_lambda" / "dm_control-pendulum-swingup-v0_1"
    model = SarsaLambda.load(run / "dm_control-pendulum-swingup-v0.zip")
    assert model.num_timesteps == 300
    np.testing.assert_allclose(model.policy.tile_coder.tile_widths, package_tilings()[env_id]["tile_widths"])
