"""Models move between Python versions: files written under the oldest supported Python and the newest
(tests/data, by make_cross_version_models.py) load under the running one with the weights, the tiling and the replay
buffer their writer had. A learning-rate lambda, pickled as a code object of its writer's Python, loads where that
Python's code objects unpickle; elsewhere it keeps the class's default with SB3's warning, and custom_objects replaces
it. .ci/run runs this module under both Pythons, so each reads the other's files."""

import json
import pathlib
import sys
import warnings

import numpy as np
import pytest
from conftest import LineWalkEnv
from stable_baselines3.common.envs import IdentityEnvBox

from sb3_er import ER, SarsaLambda, TileQPolicy

DATA = pathlib.Path(__file__).parent / "data"
TAGS = sorted(path.stem.removeprefix("models_") for path in DATA.glob("models_py*.json"))
PROBES = np.linspace(0.0, 10.0, 11)[:, None]
BOX_PROBES = np.linspace(-1.0, 1.0, 9)[:, None]
HERE = f"py{sys.version_info.major}{sys.version_info.minor}"


def record(tag: str) -> dict:
    return json.loads((DATA / f"models_{tag}.json").read_text())


def test_the_fixtures_come_from_two_pythons():
    assert {"py310", "py313"} <= set(TAGS)


@pytest.mark.parametrize("tag", TAGS)
def test_a_model_with_a_learning_rate_lambda_loads(tag):
    expected = record(tag)
    path = DATA / f"sarsa_lambda_{tag}.zip"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model = SarsaLambda.load(path)
    lost = [str(w.message) for w in caught if "Could not deserialize" in str(w.message)]
    if tag == HERE:  # its writer's bytecode runs here
        assert lost == []
        assert model.learning_rate(0.5) == pytest.approx(expected["sarsa_lambda_learning_rate_at_half"])
    else:  # bytecode of another Python (which would unpickle, then compute something else): SB3's warning, the default
        assert len(lost) == 1 and lost[0].startswith("Could not deserialize object learning_rate.")
        assert "custom_objects" in lost[0]
        assert model.learning_rate == 0.2 and model.current_learning_rate == 0.2
    np.testing.assert_allclose(model.policy.q_values(PROBES), expected["sarsa_lambda_q"], rtol=1e-12, atol=1e-12)
    assert model.trace_lambda == 0.9 and model.num_timesteps == 400

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        replaced = SarsaLambda.load(path, custom_objects={"learning_rate": lambda progress: 0.1 + 0.1 * progress})
    assert replaced.learning_rate(0.5) == pytest.approx(expected["sarsa_lambda_learning_rate_at_half"])
    replaced.set_env(LineWalkEnv())
    replaced.learn(100, reset_num_timesteps=False)
    assert replaced.num_timesteps == 500


@pytest.mark.parametrize("allow_pickle", [True, False])
@pytest.mark.parametrize("tag", TAGS)
def test_a_model_its_buffer_and_its_policy_file_load(tag, allow_pickle):
    expected = record(tag)
    model = ER.load(DATA / f"er_box_{tag}.zip", env=IdentityEnvBox(eps=0.5), allow_pickle=allow_pickle)
    np.testing.assert_allclose(model.policy.q_values(BOX_PROBES), expected["er_box_q"], rtol=1e-12, atol=1e-12)
    for suffix in ("pkl", "npz"):
        if suffix == "pkl" and not allow_pickle:
            with pytest.raises(ValueError, match="refused with allow_pickle=False"):
                model.load_replay_buffer(DATA / f"er_box_{tag}.pkl", allow_pickle=False)
            continue
        model.load_replay_buffer(DATA / f"er_box_{tag}.{suffix}", truncate_last_traj=False, allow_pickle=allow_pickle)
        assert model.replay_buffer.n_transitions == expected["er_box_transitions"]
        assert model.replay_buffer.open_length == expected["er_box_open_length"]
    model.learn(100)
    assert model.replay_buffer.n_transitions == expected["er_box_transitions"] + 100
    policy = TileQPolicy.load(DATA / f"er_box_{tag}.pth", allow_pickle=allow_pickle)
    np.testing.assert_allclose(policy.q_values(BOX_PROBES), expected["er_box_q"], rtol=1e-12, atol=1e-12)
    fresh = ER("TileQ", IdentityEnvBox(eps=0.5), policy_kwargs=dict(n_tilings=4, memory_size=2**10))
    fresh.set_parameters(DATA / f"er_box_{tag}.zip")
    np.testing.assert_allclose(fresh.policy.q_values(BOX_PROBES), expected["er_box_q"], rtol=1e-12, atol=1e-12)


def _as_if_saved_under(path: pathlib.Path, version: str) -> None:
    """Rewrite the Python version in the system information SB3 saves into a model zip."""
    import re
    import zipfile

    with zipfile.ZipFile(path) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    members["system_info.txt"] = re.sub(rb"Python: \S+", f"Python: {version}".encode(), members["system_info.txt"])
    with zipfile.ZipFile(path, "w") as archive:
        for name, content in members.items():
            archive.writestr(name, content)


def test_bytecode_of_another_python_is_not_run(tmp_path):
    """A function pickled under another Python minor version unpickles without an error and computes something else
    (a lambda of 3.13 read by 3.11 returned its argument): such an entry is treated as one that cannot be unpickled,
    whatever its bytes, while pickles without bytecode (the spaces, the generators) load as before."""
    path = tmp_path / "model.zip"
    SarsaLambda("TileQ", LineWalkEnv(), seed=0, learning_rate=lambda p: 0.3 * p).save(path)
    major, minor = sys.version_info[:2]
    _as_if_saved_under(path, f"{major}.{minor + 1}.0")
    with pytest.warns(UserWarning, match=rf"learning_rate(?s:.*)Python {major}\.{minor + 1} bytecode"):
        model = SarsaLambda.load(path)
    assert model.learning_rate == 0.2
    assert model.observation_space == LineWalkEnv().observation_space
    _as_if_saved_under(path, f"{major}.{minor}.9")  # another patch release runs the same bytecode
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert SarsaLambda.load(path).learning_rate(0.5) == pytest.approx(0.15)
