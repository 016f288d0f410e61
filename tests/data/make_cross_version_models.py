"""Writes the cross-version fixtures of tests/test_cross_version.py under the running Python:
``sarsa_lambda_py<XY>.zip`` (a learning-rate lambda, pickled as a code object of this Python), ``er_box_py<XY>.zip``
with its replay buffer as ``.pkl`` and ``.npz``, ``er_box_py<XY>.pth`` (the policy file), and ``models_py<XY>.json``:
the Python version and the Q-values the writer computed at fixed probes, which a reader under any other Python must
find again.

Run it with each Python the CI tests (the oldest supported and the newest):
``python tests/data/make_cross_version_models.py``.
"""

import json
import pathlib
import sys

import numpy as np
from stable_baselines3.common.envs import IdentityEnvBox

HERE = pathlib.Path(__file__).parent
sys.path.insert(0, str(HERE.parent))

from conftest import LineWalkEnv  # noqa: E402

from sb3_er import ER, SarsaLambda  # noqa: E402

PROBES = np.linspace(0.0, 10.0, 11)[:, None]
BOX_PROBES = np.linspace(-1.0, 1.0, 9)[:, None]
TABLE = dict(n_tilings=4, memory_size=2**10)


def main() -> None:
    tag = f"py{sys.version_info.major}{sys.version_info.minor}"
    sarsa = SarsaLambda(
        "TileQ",
        LineWalkEnv(),
        seed=0,
        trace_lambda=0.9,
        learning_rate=lambda progress: 0.1 + 0.1 * progress,
        policy_kwargs=dict(**TABLE, tile_widths=[1.0]),
    ).learn(400)
    sarsa.save(HERE / f"sarsa_lambda_{tag}.zip")
    er = ER("TileQ", IdentityEnvBox(eps=0.5), seed=0, policy_kwargs=TABLE).learn(250)  # 50 steps of an episode open
    er.save(HERE / f"er_box_{tag}.zip")
    er.save_replay_buffer(HERE / f"er_box_{tag}.pkl")
    er.save_replay_buffer(HERE / f"er_box_{tag}.npz")
    er.policy.save(HERE / f"er_box_{tag}.pth")
    record = {
        "python": sys.version.split()[0],
        "sarsa_lambda_q": sarsa.policy.q_values(PROBES).tolist(),
        "sarsa_lambda_learning_rate_at_half": sarsa.learning_rate(0.5),
        "er_box_q": er.policy.q_values(BOX_PROBES).tolist(),
        "er_box_transitions": int(er.replay_buffer.n_transitions),
        "er_box_open_length": int(er.replay_buffer.open_length),
    }
    (HERE / f"models_{tag}.json").write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    main()
