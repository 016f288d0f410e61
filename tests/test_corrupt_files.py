"""Saved replay buffers and models that were corrupted (bit flips, truncations) or crafted (consistent checksums, bad
values) are refused with an error naming the file and the field, never a crash; the model keeps its buffer and
weights; loading without pickle runs nothing from the file."""

import io
import json
import pickle
import subprocess
import sys
import tempfile
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
from conftest import LineWalkEnv
from hypothesis import given, settings
from hypothesis import strategies as st

from sb3_er import ER, SarsaLambda, TrajectoryReplayBuffer
from sb3_er.common.buffers import _npz_bytes, field_checksum

KWARGS = dict(policy_kwargs=dict(n_tilings=8, memory_size=2**15, tile_widths=[0.7]), exploration_rate=0.1, seed=0)
WORKER = Path(__file__).parent / "corruption_worker.py"


# --- bit flips and truncations, in a subprocess ----------------------------------------------------------------------


@pytest.fixture(scope="module")
def corruption_report(tmp_path_factory):
    directory = tmp_path_factory.mktemp("corrupt")
    run = subprocess.run([sys.executable, str(WORKER), str(directory)], capture_output=True, text=True, timeout=600)
    rows = [json.loads(line) for line in run.stdout.splitlines() if line.startswith("{")]
    last = rows[-1].get("case", "the last") if rows else "none"
    assert run.returncode == 0, f"the worker died (status {run.returncode}) after case {last!r}:\n{run.stderr[-3000:]}"
    assert rows[-1] == {"kind": "done"}
    return directory, rows[:-1]


def test_corrupt_buffers_are_refused_naming_file_and_field(corruption_report):
    directory, rows = corruption_report
    buffers = [row for row in rows if row["kind"] == "buffer"]
    flipped_fields = {row["field"] for row in buffers if row["field"]}
    assert {
        "observations",
        "slots",
        "actions",
        "rewards",
        "visits",
        "trajectory_length",
        "trajectory_next_slots",
        "open_new_features",
        "meta",
    } <= flipped_fields  # every field was hit, in the pickle or the npz
    for row in buffers:
        if row["outcome"] == "loaded":  # a flip pickle never reads (a memo index): the data must be exactly as saved
            assert row["intact"], row
            continue
        assert str(directory) in row["message"], row
        assert row["kept"], row
        if row["field"] and "flip" in row["case"]:
            assert repr(row["field"]) in row["message"] or f"'{row['field']}.npy'" in row["message"], row
    assert sum(row["outcome"] == "error" for row in buffers) > 0.95 * len(buffers)


def test_corrupt_models_are_refused_naming_file_and_member(corruption_report):
    directory, rows = corruption_report
    models = [row for row in rows if row["kind"] == "model"]
    assert {row["field"] for row in models if row["field"]} >= {"data", "policy.pth", "pytorch_variables.pth"}
    assert sum(row["outcome"] == "error" for row in models) > 0.95 * len(models)
    for row in models:
        if row["outcome"] == "loaded":  # a flip in a deflate stream's unused bits: every member must read as saved
            assert row["intact"], row
            continue
        assert row["outcome"] == "error", row  # every member is checked, also those SB3 never reads
        assert str(directory / "model.zip") in row["message"], row
        if row["field"] and "flip" in row["case"]:
            assert repr(row["field"]) in row["message"], row


# --- crafted buffers: checksums consistent, values bad ---------------------------------------------------------------


@pytest.fixture(scope="module")
def saved_buffers():
    """(source model, its buffer state) without and with pruning."""
    states = {}
    for prune in (None, "coverage"):
        model = ER("TileQ", LineWalkEnv(), replay_buffer_kwargs=dict(prune=prune), **KWARGS).learn(300)
        while model.replay_buffer.open_length == 0:  # an episode in progress, so the open trajectory's fields count
            model.learn(3, reset_num_timesteps=False)
        assert model.replay_buffer.n_trajectories > 2
        states[prune] = model
    return states


def crafted(state: dict) -> dict:
    state = {name: (value.copy() if isinstance(value, np.ndarray) else value) for name, value in state.items()}
    state.pop("checksums", None)
    return state


def sealed(state: dict) -> dict:
    """The state with checksums that match it: a file crafted to pass the integrity check."""
    state = dict(state)
    state.pop("checksums", None)
    state["checksums"] = {name: field_checksum(value) for name, value in state.items()}
    return state


class _Pickled:
    """Pickles as a TrajectoryReplayBuffer with the given state (the path pickle.load takes for a real buffer)."""

    def __init__(self, state):
        self.state = state

    def __reduce__(self):
        return object.__new__, (TrajectoryReplayBuffer,), self.state


def write_buffer(path: Path, state: dict) -> Path:
    if path.suffix == ".npz":
        path.write_bytes(_npz_bytes(state))
    else:
        path.write_bytes(pickle.dumps(_Pickled(state)))
    return path


def assert_refused(model_with_buffer, path: Path, field: str) -> None:
    target = ER("TileQ", LineWalkEnv(), replay_buffer_kwargs=model_with_buffer.replay_buffer_kwargs, **KWARGS)
    target.learn(45)
    previous, stored = target.replay_buffer, target.replay_buffer.n_transitions
    with pytest.raises(ValueError, match="replay buffer field") as refusal:
        target.load_replay_buffer(path)
    assert str(path) in str(refusal.value) and repr(field) in str(refusal.value)
    assert target.replay_buffer is previous and previous.n_transitions == stored
    target.replay(3)  # the model goes on with its previous buffer


def _entry(name, value):
    def corrupt(state, coder):
        state[name] = value(state, coder) if callable(value) else value

    return corrupt


def _set(name, index, value):
    def corrupt(state, coder):
        state[name][index] = value(state, coder) if callable(value) else value

    return corrupt


def _shift_observation(state, coder):
    state["observations"][2, 0] += coder.tile_widths[0] * 3.3  # other tiles than the stored ones


def _unvisit(state, coder):
    state["visits"][state["slots"][0, 0] * coder.stride + state["actions"][0]] = 0


CRAFTED = {
    "slot out of range": ("slots", _set("slots", (3, 1), lambda s, c: c.n_slots)),
    "slot of another tile": ("slots", _set("slots", (3, 1), lambda s, c: (s["slots"][3, 1] + 1) % c.n_slots)),
    "negative slot": ("trajectory_next_slots", _set("trajectory_next_slots", (0, 0), -1)),
    "action out of range": ("actions", _set("actions", 4, lambda s, c: c.n_actions)),
    "negative action": ("actions", _set("actions", 0, -3)),
    "NaN reward": ("rewards", _set("rewards", 1, np.nan)),
    "NaN observation": ("observations", _set("observations", (5, 0), np.nan)),
    "observation moved": ("slots", _shift_observation),
    "observations of another width": (
        "observations",
        _entry("observations", lambda s, c: s["observations"][:, [0, 0]]),
    ),
    "trajectory longer than its rows": (
        "trajectory_length",
        _set("trajectory_length", 0, lambda s, c: s["trajectory_length"][0] + 5),
    ),
    "empty trajectory": ("trajectory_length", _set("trajectory_length", 1, 0)),
    "trajectory start off": (
        "trajectory_start",
        _set("trajectory_start", 1, lambda s, c: s["trajectory_start"][1] + 1),
    ),
    "terminal flags as integers": (
        "trajectory_terminated",
        _entry("trajectory_terminated", lambda s, c: s["trajectory_terminated"].astype(np.int64)),
    ),
    "infinite last observation": ("trajectory_next_obs", _set("trajectory_next_obs", (0, 0), np.inf)),
    "open trajectory beyond the rows": ("open_length", _entry("open_length", lambda s, c: len(s["actions"]) + 1)),
    "open s' of another shape": ("open_next_obs", _entry("open_next_obs", np.zeros(3))),
    "visit count 2": ("visits", _set("visits", 7, 2)),
    "stored feature unvisited": ("visits", _unvisit),
    "visits of another length": ("visits", _entry("visits", lambda s, c: s["visits"][:-1])),
    "visits as floats": ("visits", _entry("visits", lambda s, c: s["visits"].astype(np.float64))),
    "capacity 0": ("capacity", _entry("capacity", 0)),
    "capacity below the rows": ("observations", _entry("capacity", lambda s, c: len(s["actions"]) - 1)),
    "capacity a string": ("capacity", _entry("capacity", "1000")),
    "tilings a string": ("tile_coder_config", lambda s, c: s["tile_coder_config"].update(n_tilings="8")),
    "coder without a setting": ("tile_coder_config", lambda s, c: s["tile_coder_config"].pop("wrap_periods")),
    "unknown prune": ("prune", _entry("prune", "everything")),
    "prune threshold 2": ("prune_threshold", _entry("prune_threshold", 2.0)),
    "missing field": ("rewards", lambda s, c: s.pop("rewards")),
}
CRAFTED_PRUNED = {
    "new feature out of range": (
        "open_new_features",
        _entry("open_new_features", lambda s, c: np.array([c.n_weights])),
    ),
    "covered beyond the open rows": ("open_covered", _entry("open_covered", lambda s, c: s["open_length"] + 1)),
    "more pruned than closed": ("pruned", _entry("pruned", (1, 5, 0))),
    "pruned counts not a triple": ("pruned", _entry("pruned", (1, 2))),
}


@pytest.mark.parametrize("suffix", [".pkl", ".npz"])
@pytest.mark.parametrize("case", list(CRAFTED) + list(CRAFTED_PRUNED))
def test_crafted_buffer_fields_are_refused_by_name(case, suffix, saved_buffers, tmp_path):
    prune = "coverage" if case in CRAFTED_PRUNED else None
    field, corrupt = {**CRAFTED, **CRAFTED_PRUNED}[case]
    source = saved_buffers[prune]
    state = crafted(source.replay_buffer.__getstate__())
    corrupt(state, source.policy.tile_coder)
    assert_refused(source, write_buffer(tmp_path / f"crafted{suffix}", sealed(state)), field)


@pytest.mark.parametrize("suffix", [".pkl", ".npz"])
@pytest.mark.parametrize("field", ["slots", "rewards", "trajectory_length", "visits", "open_length", "prune"])
def test_a_field_changed_after_saving_fails_its_checksum(field, suffix, saved_buffers, tmp_path):
    source = saved_buffers[None]
    state = source.replay_buffer.__getstate__()
    state = {**state, "checksums": dict(state["checksums"])}
    value = state[field]
    state[field] = value.copy() if isinstance(value, np.ndarray) else value
    if isinstance(value, np.ndarray):
        state[field].reshape(-1)[0] += 1
    else:
        state[field] = "coverage" if field == "prune" else value + 1
    path = write_buffer(tmp_path / f"changed{suffix}", state)
    with pytest.raises(ValueError, match=f"{path}: replay buffer field '{field}': does not match its checksum"):
        ER("TileQ", LineWalkEnv(), **KWARGS).load_replay_buffer(path)


INDEX_FIELDS = {"slots": "n_slots", "trajectory_next_slots": "n_slots", "actions": "n_actions"}


@settings(max_examples=40, deadline=None)
@given(
    field=st.sampled_from(sorted(INDEX_FIELDS)),
    position=st.floats(0.0, 1.0, exclude_max=True),
    beyond=st.integers(0, 2**62),
    negative=st.booleans(),
    suffix=st.sampled_from([".pkl", ".npz"]),
)
def test_any_index_out_of_range_anywhere_is_refused(saved_buffers, field, position, beyond, negative, suffix):
    """An index a kernel would follow, at any row and of any size outside its range, never reaches a kernel."""
    source = saved_buffers[None]
    coder = source.policy.tile_coder
    state = crafted(source.replay_buffer.__getstate__())
    flat = state[field].reshape(-1)
    flat[int(position * flat.size)] = -1 - beyond if negative else getattr(coder, INDEX_FIELDS[field]) + beyond
    with tempfile.TemporaryDirectory() as directory:
        assert_refused(source, write_buffer(Path(directory) / f"buffer{suffix}", sealed(state)), field)


def test_buffers_saved_without_checksums_are_still_checked(saved_buffers, tmp_path):
    """Files from before checksums existed load when sound and are checked field by field all the same."""
    source = saved_buffers[None]
    state = crafted(source.replay_buffer.__getstate__())
    model = ER("TileQ", LineWalkEnv(), **KWARGS)
    model.load_replay_buffer(write_buffer(tmp_path / "old.pkl", state), truncate_last_traj=False)
    assert model.replay_buffer.n_transitions == source.replay_buffer.n_transitions
    state["actions"][0] = 99
    assert_refused(source, write_buffer(tmp_path / "old_bad.pkl", state), "actions")


def test_npz_and_pickle_buffers_restore_the_same_buffer(saved_buffers, tmp_path):
    for source in saved_buffers.values():
        source.save_replay_buffer(tmp_path / "buffer.npz")
        source.save_replay_buffer(tmp_path / "buffer")
        from_npz, from_pickle = (
            ER("TileQ", LineWalkEnv(), replay_buffer_kwargs=source.replay_buffer_kwargs, **KWARGS) for _ in range(2)
        )
        from_npz.load_replay_buffer(tmp_path / "buffer.npz", truncate_last_traj=False, allow_pickle=False)
        from_pickle.load_replay_buffer(tmp_path / "buffer.pkl", truncate_last_traj=False)
        for loaded in (from_npz, from_pickle):
            assert loaded.replay_buffer.__getstate__()["checksums"] == source.replay_buffer.__getstate__()["checksums"]
        assert not list(tmp_path.glob("*.partial*"))


# --- loading runs no code from the file unless pickles are allowed ---------------------------------------------------

RAN = []


def _record_run(value):
    RAN.append(value)
    return 0.1


class _Payload:
    """Unpickling this calls _record_run: the stand-in for code a crafted file would run."""

    def __reduce__(self):
        return _record_run, ("ran",)


def test_a_pickled_buffer_runs_code_only_when_pickles_are_allowed(tmp_path):
    RAN.clear()
    path = tmp_path / "payload.pkl"
    path.write_bytes(pickle.dumps(_Payload()))
    model = ER("TileQ", LineWalkEnv(), **KWARGS)
    with pytest.raises(ValueError, match="refused with allow_pickle=False"):
        model.load_replay_buffer(path, allow_pickle=False)
    renamed = tmp_path / "payload.npz"  # a pickle named .npz is never unpickled
    renamed.write_bytes(path.read_bytes())
    with pytest.raises(ValueError, match="never unpickled"):
        model.load_replay_buffer(renamed)
    assert RAN == []
    with pytest.raises(ValueError, match="holds a float, not a TrajectoryReplayBuffer"):
        model.load_replay_buffer(path)  # the default, as in SB3: the file's code runs before any check can
    assert RAN == ["ran"]


def test_a_model_zip_runs_code_only_when_pickles_are_allowed(tmp_path):
    RAN.clear()
    model = ER("TileQ", LineWalkEnv(), **KWARGS)
    model.learning_rate = _Payload()  # saved as a ":serialized:" entry, as a crafted schedule would be
    model.save(tmp_path / "payload")
    with pytest.warns(UserWarning, match=r"Could not deserialize object learning_rate(?s:.*)allow_pickle=False"):
        refused = ER.load(tmp_path / "payload.zip", allow_pickle=False)
    assert refused.learning_rate == 0.2 and RAN == []  # the class's default, as SB3 leaves an entry it cannot restore
    loaded = ER.load(tmp_path / "payload.zip", allow_pickle=False, custom_objects={"learning_rate": 0.3})
    assert loaded.learning_rate == 0.3 and RAN == []
    assert ER.load(tmp_path / "payload.zip").learning_rate == 0.1  # SB3's default unpickles: the code ran
    assert RAN == ["ran"]


# --- crafted models
# ----------------------------------------------------------------------------------------------------

CRAFTED_MODELS = {
    "gamma": ("gamma", "0.99"),
    "exploration_rate": ("exploration_rate", (0.1,)),
    "action_rng": ("action_rng", np.zeros(2, dtype=np.uint64)),
    "action_rng zero": ("action_rng", np.zeros(4, dtype=np.uint64)),
    "replay_rng": ("replay_rng", np.ones(4, dtype=np.float64)),
    "predict_rng": ("predict_rng", "seeded"),
    "num_timesteps": ("num_timesteps", -5),
    "_last_obs": ("_last_obs", np.zeros((1, 3))),
    "ep_info_buffer": ("ep_info_buffer", 7),
    "n_replays": ("n_replays", "100"),
}


@pytest.mark.parametrize("allow_pickle", [True, False])
@pytest.mark.parametrize("case", list(CRAFTED_MODELS))
def test_crafted_model_fields_are_refused_by_name(case, allow_pickle, tmp_path):
    model = ER("TileQ", LineWalkEnv(), **KWARGS).learn(100)
    name, value = CRAFTED_MODELS[case]
    setattr(model, name, value)
    model.save(tmp_path / "crafted")
    with pytest.raises(ValueError, match=name) as refusal:
        ER.load(tmp_path / "crafted.zip", allow_pickle=allow_pickle)  # without env: _last_obs is kept
    assert str(tmp_path / "crafted.zip") in str(refusal.value)


def test_bad_weights_are_refused_and_the_current_ones_kept(tmp_path):
    model = SarsaLambda("TileQ", LineWalkEnv(), **KWARGS).learn(200)
    weights = model.policy.theta_array.copy()
    other = SarsaLambda("TileQ", LineWalkEnv(), policy_kwargs=dict(n_tilings=8, memory_size=2**14, tile_widths=[0.7]))
    other.save(tmp_path / "smaller")
    with pytest.raises(
        ValueError, match=r"smaller.zip: (?s:.*)the weights theta have shape \(16384,\).*another tile coding"
    ):
        model.set_parameters(tmp_path / "smaller.zip")
    broken = model.get_parameters()
    broken["policy"]["theta"] = broken["policy"]["theta"].clone()
    broken["policy"]["theta"][3] = float("nan")
    with pytest.raises(RuntimeError, match="theta hold non-finite values"):  # PyTorch's error for a bad state dict
        model.set_parameters(broken)
    np.testing.assert_array_equal(model.policy.theta_array, weights)
    model.policy.theta_array[3] = np.inf  # a diverged model saved as it was
    model.save(tmp_path / "diverged")
    with pytest.raises(
        ValueError, match=r"diverged.zip: (?s:.*)the weights theta hold non-finite values \(at indices \[3\]\)"
    ):
        SarsaLambda.load(tmp_path / "diverged.zip")


@pytest.mark.parametrize("where", ["SB3's save", "writing the file"])
def test_a_failed_save_leaves_the_previous_file(tmp_path, monkeypatch, where):
    model = SarsaLambda("TileQ", LineWalkEnv(), **KWARGS).learn(100)
    model.save(tmp_path / "model")
    saved = (tmp_path / "model.zip").read_bytes()
    write_bytes = Path.write_bytes

    def fail(target, *args, **kwargs):
        if isinstance(target, Path):
            write_bytes(target, b"half a file")
        else:
            target.write(b"half a file")
        raise OSError("disk full")

    if where == "SB3's save":
        monkeypatch.setattr("stable_baselines3.common.base_class.save_to_zip_file", fail)
    else:
        monkeypatch.setattr(Path, "write_bytes", fail)
    with pytest.raises(OSError, match="disk full"):
        model.save(tmp_path / "model")
    monkeypatch.undo()
    assert (tmp_path / "model.zip").read_bytes() == saved and not list(tmp_path.glob("*.partial*"))
    assert zipfile.ZipFile(tmp_path / "model.zip").testzip() is None


def _rewrite_data(path: Path, change) -> None:
    with zipfile.ZipFile(path) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    data = json.loads(members["data"])
    change(data)
    members["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(path, "w") as archive:
        for name, content in members.items():
            archive.writestr(name, content)


def test_an_entry_that_cannot_be_unpickled_is_left_at_its_default_with_sb3s_warning(tmp_path):
    """SB3's test_load_invalid_object: an entry that cannot be unpickled is left at the class's default with a warning
    pointing to custom_objects, which replaces it without a warning."""
    import base64

    path = tmp_path / "model.zip"
    SarsaLambda("TileQ", LineWalkEnv(), learning_rate=lambda _: 0.3, **KWARGS).save(path)

    def corrupt(data):
        entry = data["learning_rate"]
        raw = base64.b64decode(entry[":serialized:"]).replace(b"CodeType", b"CodeTyps")
        entry[":serialized:"] = base64.b64encode(raw).decode()

    _rewrite_data(path, corrupt)
    with pytest.warns(UserWarning, match=r"Could not deserialize object learning_rate.*custom_objects"):
        loaded = SarsaLambda.load(path)
    assert loaded.learning_rate == 0.2 and loaded.current_learning_rate == 0.2  # SarsaLambda's default
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        loaded = SarsaLambda.load(path, custom_objects={"learning_rate": 0.3})
    assert loaded.learning_rate == 0.3


@pytest.mark.parametrize("entry", ["observation_space", "action_space", "policy_class", "policy_kwargs"])
def test_an_entry_the_weights_or_tiling_need_is_refused_when_it_cannot_be_restored(entry, tmp_path):
    """The spaces, the tiling settings and the policy class lay out the weights and the buffer: an entry of them that
    neither its pickle nor its plain copy restores is refused by name (custom_objects still replaces it)."""
    import base64

    path = tmp_path / "model.zip"
    model = SarsaLambda("TileQ", LineWalkEnv(), **KWARGS)
    model.save(path)

    def break_entry(data):
        # a pickle that cannot be loaded here (a module this environment lacks), and no plain copy
        data[entry] = {":serialized:": base64.b64encode(b"cmodule_of_another_environment\nSpace\n.").decode()}
        data["_plain_state"].pop(entry, None)

    _rewrite_data(path, break_entry)
    with pytest.raises(ValueError, match=rf"model.zip: data entry '{entry}' cannot be restored.*custom_objects"):
        SarsaLambda.load(path)
    replacement = {
        "observation_space": model.observation_space,
        "action_space": model.action_space,
        "policy_class": type(model.policy),
        "policy_kwargs": model.policy_kwargs,
    }[entry]
    SarsaLambda.load(path, custom_objects={entry: replacement})


def test_a_plain_copy_that_disagrees_with_its_type_is_refused(tmp_path):
    """A crafted plain copy (an array of the wrong dtype, a space with mismatched bounds) is refused by name."""
    path = tmp_path / "model.zip"
    ER("TileQ", LineWalkEnv(), **KWARGS).learn(50).save(path)

    def bad_rng(data):
        data["_plain_state"]["action_rng"] = {"__ndarray__": ["|O", [4], [1, 2, 3, 4]]}

    _rewrite_data(path, bad_rng)
    with pytest.raises(ValueError, match=r"data entry 'action_rng': expected a numeric dtype, got '\|O'"):
        ER.load(path, allow_pickle=False)
    ER("TileQ", LineWalkEnv(), **KWARGS).save(path)

    def bad_space(data):
        space = data["_plain_state"]["observation_space"]["__space__"]
        space["high"] = {"__ndarray__": ["<f8", [2], [1.0, 2.0]]}

    _rewrite_data(path, bad_space)
    with pytest.raises(ValueError, match=r"data entry 'observation_space': malformed Box space"):
        ER.load(path, allow_pickle=False)


def test_set_parameters_reads_every_member_as_load_does(tmp_path):
    """set_parameters from a file checks its members as load does: a flipped byte in the deflated weights is a
    ValueError naming the file and the member, and the weights in place stay; a sound file, by path or stream, sets
    them."""
    source = SarsaLambda("TileQ", LineWalkEnv(), **{**KWARGS, "seed": 1}).learn(300)
    source.save(tmp_path / "source.zip")
    model = SarsaLambda("TileQ", LineWalkEnv(), **{**KWARGS, "seed": 2}).learn(100)
    weights = model.policy.theta_array.copy()
    data = (tmp_path / "source.zip").read_bytes()
    with zipfile.ZipFile(tmp_path / "source.zip") as archive:
        info = archive.getinfo("policy.pth")
        start = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra)
    damaged = bytearray(data)
    damaged[start + info.compress_size // 2] ^= 0x20
    (tmp_path / "damaged.zip").write_bytes(bytes(damaged))
    with pytest.raises(ValueError, match=r"damaged\.zip: member 'policy\.pth' of the zip is corrupt"):
        model.set_parameters(tmp_path / "damaged.zip")
    np.testing.assert_array_equal(model.policy.theta_array, weights)
    model.set_parameters(tmp_path / "source")  # SB3's ".zip" added
    np.testing.assert_array_equal(model.policy.theta_array, source.policy.theta_array)
    other = SarsaLambda("TileQ", LineWalkEnv(), **{**KWARGS, "seed": 3})
    with open(tmp_path / "source.zip", "rb") as stream:
        other.set_parameters(stream)
        assert not stream.closed
    np.testing.assert_array_equal(other.policy.theta_array, source.policy.theta_array)
    with pytest.raises(TypeError):
        other.set_parameters(io.StringIO("not binary"))


def _rewritten(path: Path, out: Path, method: int, extra: dict[str, bytes] | None = None) -> None:
    """`path`'s members written to `out` with compression `method`, plus the members `extra`."""
    with zipfile.ZipFile(path) as archive, zipfile.ZipFile(out, "w", method) as copy:
        for info in archive.infolist():
            copy.writestr(info.filename, archive.read(info))
        for name, content in (extra or {}).items():
            copy.writestr(name, content)


@pytest.mark.parametrize("method", [zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED, zipfile.ZIP_BZIP2, zipfile.ZIP_LZMA])
def test_a_damaged_member_is_named_whatever_its_compression(tmp_path, method):
    """A zip written by another tool with any of Python's compression methods loads; a flipped byte in its weights is
    a ValueError naming the file and the member for load and set_parameters alike, never the decompressor's own
    error, and the weights in place stay."""
    model = SarsaLambda("TileQ", LineWalkEnv(), **KWARGS).learn(200)
    model.save(tmp_path / "model.zip")
    _rewritten(tmp_path / "model.zip", tmp_path / "other.zip", method)
    loaded = SarsaLambda.load(tmp_path / "other.zip")
    np.testing.assert_array_equal(loaded.policy.theta_array, model.policy.theta_array)
    data = bytearray((tmp_path / "other.zip").read_bytes())
    with zipfile.ZipFile(tmp_path / "other.zip") as archive:
        info = archive.getinfo("policy.pth")
    start = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra)
    data[start + info.compress_size // 2] ^= 0x20
    (tmp_path / "damaged.zip").write_bytes(bytes(data))
    weights = loaded.policy.theta_array.copy()
    for attempt in (
        lambda: SarsaLambda.load(tmp_path / "damaged.zip"),
        lambda: loaded.set_parameters(tmp_path / "damaged.zip"),
    ):
        with pytest.raises(ValueError, match=r"damaged\.zip: member 'policy\.pth' of the zip is corrupt"):
            attempt()
    np.testing.assert_array_equal(loaded.policy.theta_array, weights)


def test_a_member_sb3_never_reads_is_checked_but_never_held(tmp_path):
    """A member SB3 never reads (a note added to the zip) is read through for its CRC but not kept: one that inflates
    to 64 MiB costs no 64 MiB of memory; flipped, it is refused by name all the same."""
    import tracemalloc

    model = SarsaLambda("TileQ", LineWalkEnv(), **KWARGS).learn(200)
    model.save(tmp_path / "model.zip")
    _rewritten(tmp_path / "model.zip", tmp_path / "noted.zip", zipfile.ZIP_DEFLATED, {"note.txt": bytes(64 << 20)})
    assert (tmp_path / "noted.zip").stat().st_size < 1 << 20
    tracemalloc.start()
    try:
        loaded = SarsaLambda.load(tmp_path / "noted.zip")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    np.testing.assert_array_equal(loaded.policy.theta_array, model.policy.theta_array)
    assert peak < 32 << 20, f"loading held {peak / 2**20:.0f} MiB"
    # a flip in a stream of zeros may decode to the same zeros (a copy from another distance): flip a note of text
    note = b"".join(b"line %d of a note\n" % i for i in range(2000))
    _rewritten(tmp_path / "model.zip", tmp_path / "noted.zip", zipfile.ZIP_DEFLATED, {"note.txt": note})
    data = bytearray((tmp_path / "noted.zip").read_bytes())
    with zipfile.ZipFile(tmp_path / "noted.zip") as archive:
        info = archive.getinfo("note.txt")
    data[info.header_offset + 30 + len(info.filename.encode()) + len(info.extra) + info.compress_size // 2] ^= 0x20
    (tmp_path / "damaged.zip").write_bytes(bytes(data))
    with pytest.raises(ValueError, match=r"member 'note\.txt' of the zip is corrupt"):
        SarsaLambda.load(tmp_path / "damaged.zip")
