"""Start-up: ``import sb3_er`` and a run import only what the run uses, and no kernel is compiled at import.

Each check runs in a fresh interpreter (a subprocess), whose ``sys.modules`` it reads; timing stays in
``benchmarks/vs_grl.py``.
"""

import json
import subprocess
import sys

import pytest

#: Packages a run of the tile-coded learners never needs: the hyperparameter and distribution extras, plotting,
#: tables, and Dyna's nearest-neighbour model (loaded when a Dyna model is first fit).
NEVER_AT_IMPORT = ("ray", "optuna", "rl_zoo3", "matplotlib", "pandas", "scipy.spatial")


def imported_after(code: str) -> dict:
    """What a fresh interpreter holds after running ``code``: its modules, and the numba kernels compiled or loaded
    (kernel name -> number of signatures) of sb3-er's kernels and the walker's simulation, where imported."""
    probe = (
        code
        + """
import json, sys
kernels = {}
for name in ("sb3_er.common.kernels", "sb3_er_envs.simplest_walker"):
    module = sys.modules.get(name)
    for attribute, value in (vars(module) if module else {}).items():
        if getattr(value, "signatures", None):
            kernels[f"{name}.{attribute}"] = len(value.signatures)
print(json.dumps({"modules": sorted(sys.modules), "kernels": kernels}))
"""
    )
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=600, check=True)
    return json.loads(result.stdout.strip().splitlines()[-1])


def loaded(modules: list[str], package: str) -> bool:
    return any(name == package or name.startswith(package + ".") for name in modules)


def test_import_sb3_er_loads_no_algorithm_module():
    state = imported_after("import sb3_er")
    assert not any(name.startswith("sb3_er.") for name in state["modules"])
    assert not loaded(state["modules"], "torch")  # not even SB3 until a name is used


@pytest.mark.parametrize("package", NEVER_AT_IMPORT)
def test_every_public_name_imports_without(package):
    state = imported_after("import sb3_er\nfrom sb3_er import *\nimport sb3_er_envs")
    assert {"sb3_er.dyna", "sb3_er.fqi", "sb3_er.lspi", "sb3_er.er"} <= set(state["modules"])
    assert not loaded(state["modules"], package), f"{package} imported by sb3_er's public names"


def test_importing_compiles_no_kernel_and_a_sarsa_run_only_the_kernels_it_calls():
    assert imported_after("from sb3_er import *\nimport sb3_er_envs")["kernels"] == {}
    run = """
import sb3_er_envs
from sb3_er import SarsaLambda
SarsaLambda("TileQ", "sb3_er/CompassWalker-v0", policy_kwargs=dict(initial_value=(0.0, 1.0), memory_size=2**16),
            seed=1).learn(600)
"""
    imported_after(run)  # a fresh install compiles the kernels and their callees once, into numba's cache
    state = imported_after(run)  # every later run loads the kernels it calls from the cache, and no other
    for package in (*NEVER_AT_IMPORT, "scipy.sparse", "sb3_er.dyna", "sb3_er.er"):
        assert not loaded(state["modules"], package), package
    kernels = {name.rsplit(".", 1)[1] for name in state["kernels"]}
    assert kernels == {
        "fill_initial_weights",
        "select_action",
        "sarsa_lambda_step",
        "clear_trace",
        "simulate_control_step",
    }
    assert set(state["kernels"].values()) == {1}, "a kernel compiled for two signatures"


@pytest.mark.parametrize("algorithm", ["SarsaLambda", "ERSigma"])
def test_an_sb3_er_id_needs_no_separate_import(tmp_path, algorithm):
    # SB3 makes the id with gymnasium.make inside BaseAlgorithm: the sb3_er/ namespace must be registered by then,
    # for a new model and for load(..., env=id), in an interpreter that never imported sb3_er_envs itself.
    path = tmp_path / "model.zip"
    run = f"""
import sys
from sb3_er import {algorithm}
assert "sb3_er_envs" not in sys.modules
model = {algorithm}("TileQ", "sb3_er/WindyCliff-v0", seed=0).learn(300)
model.save({str(path)!r})
loaded = {algorithm}.load({str(path)!r}, env="sb3_er/WindyCliff-v0")
assert loaded.get_env().num_envs == 1
"""
    assert "sb3_er_envs" in imported_after(run)["modules"]


def test_an_unknown_namespace_is_still_gymnasiums_error():
    probe = "from sb3_er import SarsaLambda\nSarsaLambda('TileQ', 'sb3_er_typo/WindyCliff-v0')"
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=600)
    assert result.returncode != 0 and "Namespace sb3_er_typo not found" in result.stderr
