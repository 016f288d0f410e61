"""The kernels' structure: every bundle field documented once, every kernel compiled for one set of argument types in
a run of every algorithm (a silent recompile would show as a second signature), and every kernel free of the GIL."""

import json
import subprocess
import sys
import typing

import numpy as np
import pytest

from sb3_er.common import kernels
from sb3_er.common.docstrings import parameter_fields
from sb3_er.common.kernels import bundles


@pytest.mark.parametrize("bundle", bundles.BUNDLES, ids=lambda bundle: bundle.__name__)
def test_every_bundle_field_is_documented_once(bundle):
    fields = parameter_fields(bundle.__doc__)
    assert list(fields) == list(bundle._fields), f"{bundle.__name__} documents {list(fields)}"
    for name, text in fields.items():
        assert len(text.split(":", 2)[2].strip()) > 10, f"{bundle.__name__}.{name} has no real description"


@pytest.mark.parametrize("bundle", bundles.BUNDLES, ids=lambda bundle: bundle.__name__)
def test_make_converts_scalars_to_their_annotated_types(bundle):
    hints = typing.get_type_hints(bundle)
    values = {name: (1 if hints[name] in (int, float, bool, np.uint64) else np.zeros(1)) for name in bundle._fields}
    made = bundles.make(bundle, **values)
    for name, value in zip(bundle._fields, made, strict=True):
        if hints[name] in (int, float, bool, np.uint64):
            assert type(value) is hints[name], (bundle.__name__, name, type(value))
    with pytest.raises(TypeError, match="missing fields"):
        bundles.make(bundle, **dict(list(values.items())[1:]))


def _kernels():
    """Every numba dispatcher of the kernels package, by qualified name."""
    import importlib
    import pkgutil

    found = {}
    for info in pkgutil.iter_modules(kernels.__path__):
        module = importlib.import_module(f"{kernels.__name__}.{info.name}")
        for name, obj in vars(module).items():
            if hasattr(obj, "signatures") and hasattr(obj, "py_func") and obj.__module__ == module.__name__:
                found[f"{info.name}.{name}"] = obj
    return found


def test_every_kernel_runs_without_the_gil():
    found = _kernels()
    assert len(found) > 30
    assert [name for name, kernel in found.items() if not kernel.targetoptions.get("nogil")] == []


RUN_EVERY_ALGORITHM = """
import json, warnings
import numpy as np
import sb3_er
from sb3_er import ER, FQI, LSPI, Dyna, ERSigma, ResidualER, ResidualERSigma, SarsaLambda
from test_kernel_bundles import _kernels
warnings.simplefilter("ignore")
small = dict(policy_kwargs=dict(n_tilings=4, memory_size=2**14))
runs = [
    (SarsaLambda, "CartPole-v1", {}),
    (ER, "CartPole-v1", dict(n_replays=3)),
    (ER, "CartPole-v1", dict(n_replays=3, replay_order="uniform", online_lambda=0.9)),
    (ER, "CartPole-v1", dict(n_replays=3, replay_order="prioritized")),
    (ERSigma, "CartPole-v1", dict(n_replays=3, policy_kwargs=dict(initial_value=(0.0, 1.0), n_tilings=4,
                                                                     memory_size=2**14))),
    (ResidualER, "MountainCar-v0", dict(n_replays=3)),
    (ResidualERSigma, "Pendulum-v1", dict(n_replays=3)),
    (Dyna, "CartPole-v1", dict(planning_steps=2, model_refit_every=50)),
    (FQI, "CartPole-v1", dict(fit_every=2, n_iterations=1)),
    (LSPI, "CartPole-v1", dict(fit_every=2, n_iterations=1)),
]
for algo, env_id, kwargs in runs:
    kwargs = {**small, **kwargs}
    model = algo("TileQ", env_id, seed=0, **kwargs).learn(600)
    model.predict(model.env.reset(), deterministic=True)
    model.predict(model.env.reset())
print(json.dumps({name: [str(s) for s in kernel.signatures] for name, kernel in _kernels().items()}))
"""


@pytest.mark.slow
def test_each_kernel_compiles_once_in_a_run_of_every_algorithm():
    """A kernel met with another argument type compiles a second version silently (float where an int was, a
    non-contiguous array, a named tuple where a plain one was): after every algorithm has learned, acted and
    predicted in one process, each kernel holds at most one compiled signature."""
    result = subprocess.run(
        [sys.executable, "-c", RUN_EVERY_ALGORITHM],
        capture_output=True,
        text=True,
        timeout=1200,
        cwd=str(__import__("pathlib").Path(__file__).parent),
    )
    assert result.returncode == 0, result.stderr[-3000:]
    signatures = json.loads(result.stdout.strip().splitlines()[-1])
    assert {name: found for name, found in signatures.items() if len(found) > 1} == {}
    assert len([name for name, found in signatures.items() if found]) >= 10, signatures
