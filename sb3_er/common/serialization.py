"""Model files without surprises: a plain (JSON) copy of what SB3 pickles, a loading path that unpickles nothing, and
the checks of a loaded model's state.

SB3 saves a model's non-JSON attributes (spaces, generators, arrays, the policy class, schedules) as cloudpickle
bytes in the zip's ``data`` entry (``":serialized:"``); unpickling them runs whatever code the file names. sb3-er also
stores each such attribute that has a plain form under :data:`PLAIN_STATE_KEY`. ``load(..., allow_pickle=False)``
rebuilds those attributes from it through SB3's ``custom_objects`` and refuses any entry that only a pickle holds, so
the file's pickles are never read. The weights are read by SB3 with ``torch.load(weights_only=True)`` either way.
"""

import base64
import io
import json
import lzma
import pathlib
import pickletools
import re
import sys
import warnings
import zipfile
import zlib
from collections import deque
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import cloudpickle
import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.save_util import is_json_serializable, open_path

from sb3_er.common.atomic import atomic_output

#: The data entry holding the plain copies of the attributes SB3 pickles.
PLAIN_STATE_KEY = "_plain_state"
#: Pickled entries that loading rebuilds from other settings (``_setup_model`` makes lr_schedule from learning_rate).
REBUILT_ON_LOAD = ("lr_schedule",)
#: Entries a model cannot be rebuilt without: the spaces and the tiling settings, on which the weights' layout and the
#: replay buffer's stored tiles depend, and the policy class. Any other entry that cannot be restored is left at the
#: class's default with SB3's warning, as SB3 does.
REQUIRED_ENTRIES = ("observation_space", "action_space", "policy_class", "policy_kwargs")
NUMERIC_KINDS = "biuf"
BIT_GENERATORS = ("PCG64", "PCG64DXSM", "MT19937", "Philox", "SFC64")


def _numeric_dtype(name: Any) -> np.dtype:
    try:
        dtype = np.dtype(name) if isinstance(name, str) else None
    except TypeError:
        dtype = None
    if dtype is None or dtype.kind not in NUMERIC_KINDS:
        raise ValueError(f"expected a numeric dtype, got {name!r}")
    return dtype


def encode_plain(value: Any) -> Any:
    """A JSON-native form of ``value`` (numbers, strings, lists, dicts, NumPy arrays and generators, deques, gymnasium
    Box/Discrete/MultiDiscrete spaces, torch devices, classes by name); TypeError for anything else.

    :param value: the value to encode or check.
    """
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, list):
        return [encode_plain(v) for v in value]
    if isinstance(value, tuple):
        return {"__tuple__": [encode_plain(v) for v in value]}
    if isinstance(value, dict) and all(isinstance(k, str) for k in value):
        return {"__dict__": {k: encode_plain(v) for k, v in value.items()}}
    if isinstance(value, np.ndarray) and value.dtype.kind in NUMERIC_KINDS:
        return {"__ndarray__": [value.dtype.str, list(value.shape), value.ravel().tolist()]}
    if isinstance(value, np.generic) and value.dtype.kind in NUMERIC_KINDS:
        return {"__scalar__": [value.dtype.str, value.item()]}
    if isinstance(value, np.random.Generator) and type(value.bit_generator).__name__ in BIT_GENERATORS:
        return {"__generator__": encode_plain(value.bit_generator.state)}
    if isinstance(value, deque):
        return {"__deque__": [value.maxlen, [encode_plain(v) for v in value]]}
    if isinstance(value, spaces.Box):
        return {
            "__space__": {
                "type": "Box",
                "low": encode_plain(value.low),
                "high": encode_plain(value.high),
                "dtype": value.dtype.str,
            }
        }
    if type(value) is spaces.Discrete:
        return {"__space__": {"type": "Discrete", "n": int(value.n), "start": int(value.start)}}
    if type(value) is spaces.MultiDiscrete:
        return {
            "__space__": {
                "type": "MultiDiscrete",
                "nvec": encode_plain(value.nvec),
                "start": encode_plain(value.start),
                "dtype": value.dtype.str,
            }
        }
    if isinstance(value, th.device):
        return {"__device__": str(value)}
    if isinstance(value, type):
        return {"__class__": f"{value.__module__}:{value.__qualname__}"}
    raise TypeError(f"{type(value).__name__} has no plain form")


def decode_plain(value: Any, classes: dict[str, type]) -> Any:
    """The inverse of :func:`encode_plain`, checking every part; a class is looked up in ``classes`` ("module:name"
    to class), never imported. ValueError for anything malformed.

    :param value: a plain form written by :func:`encode_plain`.
    :param classes: the classes a plain form may name, by "module:name".
    """
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, list):
        return [decode_plain(v, classes) for v in value]
    if not (isinstance(value, dict) and len(value) == 1):
        raise ValueError(f"malformed plain value {str(value)[:80]}")
    ((kind, body),) = value.items()
    if kind == "__tuple__" and isinstance(body, list):
        return tuple(decode_plain(v, classes) for v in body)
    if kind == "__dict__" and isinstance(body, dict):
        return {k: decode_plain(v, classes) for k, v in body.items()}
    if kind == "__ndarray__" and isinstance(body, list) and len(body) == 3:
        dtype, shape, data = _numeric_dtype(body[0]), body[1], body[2]
        if not (
            isinstance(shape, list)
            and all(isinstance(d, int) and not isinstance(d, bool) and d >= 0 for d in shape)
            and isinstance(data, list)
            and len(data) == int(np.prod(shape, dtype=np.int64))
        ):
            raise ValueError(f"malformed array: shape {shape!r} for {len(data) if isinstance(data, list) else data!r}")
        if not all(isinstance(x, (bool, int, float)) for x in data):
            raise ValueError("malformed array: entries must be numbers")
        try:
            return np.array(data, dtype=dtype).reshape(shape)
        except (OverflowError, ValueError, TypeError) as error:
            raise ValueError(f"malformed {dtype} array ({error})") from None
    if kind == "__scalar__" and isinstance(body, list) and len(body) == 2 and isinstance(body[1], (bool, int, float)):
        try:
            return _numeric_dtype(body[0]).type(body[1])
        except (OverflowError, ValueError, TypeError) as error:
            raise ValueError(f"malformed scalar ({error})") from None
    if kind == "__generator__":
        state = decode_plain(body, classes)
        name = state.get("bit_generator") if isinstance(state, dict) else None
        if name not in BIT_GENERATORS:
            raise ValueError(f"unknown bit generator {name!r}")
        bit_generator = getattr(np.random, name)()
        try:
            bit_generator.state = state
        except (TypeError, ValueError, KeyError) as error:
            raise ValueError(f"malformed {name} state ({error})") from None
        return np.random.Generator(bit_generator)
    if kind == "__deque__" and isinstance(body, list) and len(body) == 2 and isinstance(body[1], list):
        maxlen = body[0]
        if maxlen is not None and not (isinstance(maxlen, int) and maxlen >= 0):
            raise ValueError(f"malformed deque length {maxlen!r}")
        return deque((decode_plain(v, classes) for v in body[1]), maxlen=maxlen)
    if kind == "__space__" and isinstance(body, dict):
        return _decode_space(body, classes)
    if kind == "__device__" and isinstance(body, str):
        try:
            return th.device(body)
        except RuntimeError as error:
            raise ValueError(f"malformed device {body!r} ({error})") from None
    if kind == "__class__" and isinstance(body, str):
        if body not in classes:
            raise ValueError(f"class {body} is not among the classes this load accepts: {sorted(classes)}")
        return classes[body]
    raise ValueError(f"malformed plain value {str(value)[:80]}")


def _decode_space(body: dict[str, Any], classes: dict[str, type]) -> spaces.Space:
    kind = body.get("type")
    fields = {k: decode_plain(v, classes) for k, v in body.items() if k != "type"}
    try:
        if kind == "Box" and set(fields) == {"low", "high", "dtype"}:
            dtype = _numeric_dtype(fields["dtype"])
            low, high = np.asarray(fields["low"]), np.asarray(fields["high"])
            if low.shape != high.shape:
                raise ValueError(f"low {low.shape} and high {high.shape} differ in shape")
            return spaces.Box(low=low, high=high, shape=low.shape, dtype=dtype)
        if kind == "Discrete" and set(fields) == {"n", "start"}:
            return spaces.Discrete(fields["n"], start=fields["start"])
        if kind == "MultiDiscrete" and set(fields) == {"nvec", "start", "dtype"}:
            return spaces.MultiDiscrete(fields["nvec"], dtype=_numeric_dtype(fields["dtype"]), start=fields["start"])
    except (TypeError, AssertionError, ValueError) as error:
        raise ValueError(f"malformed {kind} space ({error})") from None
    raise ValueError(f"unsupported or malformed space {str(body)[:80]}")


def plain_state(model, exclude: list[str] | None = None, include: list[str] | None = None) -> dict[str, Any]:
    """Plain forms of the attributes that ``model.save(path, exclude, include)`` pickles (those without a JSON form);
    an attribute without a plain form (a schedule function, a custom object) is left to its pickle alone.

    :param model: the algorithm being saved.
    :param exclude: attribute names ``save`` leaves out (default None).
    :param include: attribute names ``save`` adds (default None).
    """
    excluded = (set(exclude or []) | set(model._excluded_save_params())) - set(include or [])
    state_dicts, torch_variables = model._get_torch_save_params()
    excluded |= {name.split(".")[0] for name in [*state_dicts, *torch_variables]}
    plain = {}
    for name, value in model.__dict__.items():
        if name in excluded or name == PLAIN_STATE_KEY or is_json_serializable(value):
            continue
        try:
            plain[name] = encode_plain(value)
        except TypeError:
            pass
    return plain


def resolve_zip_path(path: str | pathlib.Path) -> pathlib.Path:
    """SB3's convention (``open_path`` for reading with suffix "zip"): a path that does not exist is read with ".zip"
    appended, if that exists.

    :param path: the path as given to ``load``.
    """
    path = pathlib.Path(path)
    with_suffix = pathlib.Path(f"{path}.zip")
    if not path.exists() and with_suffix.exists():
        return with_suffix
    return path


def check_file_object(stream: Any, mode: str) -> None:
    """SB3's checks of a file object given instead of a path (``save_util.open_path``): TypeError unless it is a binary
    file or buffer (BufferedReader, BufferedWriter, BufferedRandom, BytesIO), ValueError if it is closed or cannot be
    read ("r") or written ("w").

    :param stream: the file object.
    :param mode: "r" or "w".
    """
    open_path(stream, mode)


#: The errors reading a damaged member raises, by its compression: a CRC or header mismatch (BadZipFile), a deflate,
#: LZMA or bzip2 stream that does not decode (zlib.error, LZMAError, OSError), a stream cut short (EOFError), a method
#: this Python cannot read (NotImplementedError) and an encrypted member (RuntimeError).
DAMAGED_MEMBER_ERRORS = (
    zipfile.BadZipFile,
    zlib.error,
    lzma.LZMAError,
    EOFError,
    OSError,
    NotImplementedError,
    RuntimeError,
)

#: How much of a member is read at a time: a member is never held whole unless SB3 reads it.
MEMBER_CHUNK = 1 << 20


def read_by_sb3(name: str) -> bool:
    """Whether SB3's ``load`` reads the zip member ``name``: the data entry, its version, the system information and
    every ``*.pth`` file (``save_util.load_from_zip_file``).

    :param name: the member's name.
    """
    return name in ("data", "_stable_baselines3_version", "system_info.txt") or name.endswith(".pth")


def _fresh_entry(info: zipfile.ZipInfo) -> zipfile.ZipInfo:
    """A new member like ``info`` (name, time, attributes) for another zip, with no extra field (a stale ZIP64 one)
    and the compression that zip's write gives it."""
    entry = zipfile.ZipInfo(info.filename, date_time=info.date_time)
    entry.external_attr = info.external_attr
    return entry


def read_members(
    archive: zipfile.ZipFile, copy: zipfile.ZipFile | None = None
) -> tuple[dict[str, bytes], tuple | None]:
    """Read every member of ``archive`` whole, in chunks of MEMBER_CHUNK (its CRC checked, a compressed one
    decompressed), and copy those SB3 reads (:func:`read_by_sb3`) into ``copy`` when one is given. Returns the data
    entry's and the system information's bytes by name, and the first member that cannot be read with why, or None.
    ``ZipFile.testzip`` checks the CRCs but lets a decompression error escape without the member's name; members SB3
    never reads are checked and dropped, so a crafted member that decompresses to gigabytes costs time, not memory.

    :param archive: an open zip file.
    :param copy: a zip open for writing that receives SB3's members, stored (default None: check only).
    """
    kept: dict[str, bytes] = {}
    for info in archive.infolist():
        small = info.filename in ("data", "system_info.txt")
        copied = copy is not None and read_by_sb3(info.filename)
        parts = []
        try:
            with archive.open(info) as member:
                target = copy.open(_fresh_entry(info), "w", force_zip64=True) if copied else None
                try:
                    while chunk := member.read(MEMBER_CHUNK):
                        if target is not None:
                            target.write(chunk)
                        if small:
                            parts.append(chunk)
                finally:
                    if target is not None:
                        target.close()
        except DAMAGED_MEMBER_ERRORS as error:
            return kept, (info.filename, f"{type(error).__name__}: {error}")
        if small:
            kept[info.filename] = b"".join(parts)
    return kept, None


def read_zip_data(path: str | pathlib.Path | io.BufferedIOBase) -> tuple[dict[str, Any], Any, tuple[int, int] | None]:
    """The JSON ``data`` entry of a model zip (parsed, never unpickled), after reading every member whole
    (:func:`read_members`: its CRC, and its decompression where it is compressed); the path or file object to pass on
    to SB3, or a copy in memory of SB3's members, stored, when some are compressed (``torch.load`` seeks back and forth
    in the policy's member, and each backward seek in a deflated member inflates it again from its start: a walker
    model's load took 0.8 s instead of 0.3 s); and the (major, minor) version of the Python that saved it, from the
    system information SB3 writes into the zip (None if absent). A file object is read as SB3 reads it: the zip is
    found from the end of the file, wherever the stream stands (a BytesIO just written needs no seek), and the stream
    is left open.

    :param path: the model's file (a path or an open binary file).
    """
    source = resolve_zip_path(path) if isinstance(path, (str, pathlib.Path)) else path
    stored = None
    try:
        with zipfile.ZipFile(source) as archive:
            if any(info.compress_type != zipfile.ZIP_STORED for info in archive.infolist()):
                stored = io.BytesIO()
                with zipfile.ZipFile(stored, "w", zipfile.ZIP_STORED) as copy:
                    kept, corrupt = read_members(archive, copy)  # every member, also those SB3 never reads
            else:
                kept, corrupt = read_members(archive)
    except (zipfile.BadZipFile, ValueError, EOFError, OSError) as error:
        if isinstance(error, FileNotFoundError):
            raise
        raise ValueError(f"not a readable model zip ({type(error).__name__}: {error})") from None
    if corrupt is not None:
        raise ValueError(f"member {corrupt[0]!r} of the zip is corrupt ({corrupt[1]}): the file is damaged")
    if "data" not in kept:
        raise ValueError("the zip has no data entry")
    try:
        data = json.loads(kept["data"].decode())
    except ValueError as error:
        raise ValueError(f"the data entry is not JSON ({error})") from None
    if not isinstance(data, dict):
        raise ValueError("the data entry is not a JSON object")
    if stored is not None:
        stored.seek(0)
        source = stored
    found = re.search(rb"Python: (\d+)\.(\d+)", kept.get("system_info.txt", b""))
    return data, source, (int(found.group(1)), int(found.group(2))) if found else None


def holds_bytecode(pickled: bytes) -> bool:
    """Whether a cloudpickle string rebuilds a code object (a lambda, a function defined in ``__main__``, a closure),
    read from its opcodes without unpickling: bytecode runs only under the Python minor version that compiled it.

    :param pickled: the pickle's bytes.
    """
    try:
        return any(arg == "CodeType" for _, arg, _ in pickletools.genops(pickled))
    except Exception:  # a malformed pickle: unpickling it will say what is wrong
        return False


def _is_pickled(item: Any) -> bool:
    return isinstance(item, dict) and ":serialized:" in item


def restore_entries(
    data: dict[str, Any],
    classes: dict[str, type],
    custom_objects: dict[str, Any] | None,
    allow_pickle: bool,
    saved_python: tuple[int, int] | None = None,
) -> tuple[dict[str, Any], list[str]]:
    """SB3 ``custom_objects`` restoring every pickled entry of ``data``, and the entries that cannot be restored.

    Each pickled entry (``":serialized:"``) the caller does not replace is restored by the first that works of: its
    pickle (only with ``allow_pickle``; SB3's own unpickling, cloudpickle); its plain copy (:data:`PLAIN_STATE_KEY`);
    for ``lr_schedule``, nothing (loading rebuilds it from ``learning_rate``). An entry none restores (a schedule saved
    under another Python version, a class that cannot be imported here, a pickle refused by ``allow_pickle=False``)
    gets SB3's warning and is left out, so the model keeps the class's default for it, as SB3 does; unless it is one of
    :data:`REQUIRED_ENTRIES`, which is a ValueError naming it. A malformed plain copy (a crafted or corrupt file) is a
    ValueError too. SB3 then unpickles nothing itself.

    :param data: the zip's parsed ``data`` entry.
    :param classes: the classes a plain form may name, by "module:name".
    :param custom_objects: the caller's own replacements, which win (default None).
    :param allow_pickle: unpickle the entries (SB3's behaviour) before falling back on the plain copies.
    :param saved_python: the (major, minor) version of the Python that saved the file (default None: unknown). An
        entry holding bytecode saved under another minor version is not unpickled: code objects of one version
        unpickle under another without an error and then compute something else, or crash.
    """
    here = sys.version_info[:2]
    foreign = saved_python is not None and tuple(saved_python) != here
    restored = dict(custom_objects or {})
    plain = data.get(PLAIN_STATE_KEY, {})
    if not isinstance(plain, dict):
        raise ValueError(f"data entry {PLAIN_STATE_KEY!r} is not a JSON object")
    left_out = []
    for key, item in data.items():
        if key in restored or not _is_pickled(item):
            continue
        if key in REBUILT_ON_LOAD:
            restored[key] = None
            continue
        problem = "allow_pickle=False refuses to unpickle it"
        if allow_pickle:
            try:
                pickled = base64.b64decode(str(item[":serialized:"]).encode())
                if foreign and holds_bytecode(pickled):
                    problem = (
                        f"it holds Python {saved_python[0]}.{saved_python[1]} bytecode, which Python "
                        f"{here[0]}.{here[1]} cannot run"
                    )
                else:
                    restored[key] = cloudpickle.loads(pickled)
                    continue
            except Exception as error:  # anything a pickle of another Python, or a missing module, raises
                problem = f"{type(error).__name__}: {error}"
        if key in plain:
            try:
                restored[key] = decode_plain(plain[key], classes)
            except ValueError as error:  # written by save, so a crafted or corrupt file
                raise ValueError(f"data entry {key!r}: {error}") from None
            continue
        if key in REQUIRED_ENTRIES:
            raise ValueError(
                f"data entry {key!r} cannot be restored ({problem}), and the model cannot be rebuilt without it: "
                f"pass custom_objects={{{key!r}: ...}}"
            )
        warnings.warn(  # SB3's message (save_util.json_to_data), naming the entry left at its default
            f"Could not deserialize object {key}. Consider using `custom_objects` argument to replace this object.\n"
            f"Exception: {problem}",
            stacklevel=3,
        )
        left_out.append(key)
    return restored, left_out


#: zlib's compression level of a saved model's zip entries (zlib's default; its fastest, 1, gives a file 1.6 times as
#: large on the walker for 0.05 s less).
MODEL_COMPRESSION_LEVEL = 6


def deflated_zip(archive: bytes) -> bytes:
    """A copy of the zip ``archive`` with every entry deflated. SB3's ``save`` stores them uncompressed, and a
    tile-coded model's weights are mostly their initial value, so the file is tens to hundreds of times smaller
    (``benchmarks/model_size.py``). SB3's ``load`` (and sb3-er's) read either kind.

    :param archive: the bytes of a zip file, as SB3's ``save`` writes it.
    """
    out = io.BytesIO()
    level = MODEL_COMPRESSION_LEVEL
    with (
        zipfile.ZipFile(io.BytesIO(archive)) as source,
        zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED, compresslevel=level) as copy,
    ):
        for info in source.infolist():
            copy.writestr(
                _fresh_entry(info), source.read(info), compress_type=zipfile.ZIP_DEFLATED, compresslevel=level
            )
    return out.getvalue()


def zip_without_entries(source: Any, left_out: list[str]) -> Any:
    """The model zip ``source`` with the keys ``left_out`` dropped from its ``data`` entry (a copy in memory of SB3's
    members, stored), so that SB3's load leaves those attributes at the class's defaults, as it does for an entry it
    cannot unpickle; ``source`` itself when nothing is left out.

    :param source: the model's zip (a path or an open binary file), read whole before (:func:`read_zip_data`).
    :param left_out: the data keys to drop.
    """
    if not left_out:
        return source
    out = io.BytesIO()
    with zipfile.ZipFile(source) as archive, zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as copy:
        for info in archive.infolist():
            if not read_by_sb3(info.filename):
                continue
            if info.filename == "data":
                data = json.loads(archive.read(info).decode())
                kept = {key: value for key, value in data.items() if key not in left_out}
                copy.writestr(_fresh_entry(info), json.dumps(kept, indent=4))
                continue
            with archive.open(info) as member, copy.open(_fresh_entry(info), "w", force_zip64=True) as target:
                while chunk := member.read(MEMBER_CHUNK):
                    target.write(chunk)
    out.seek(0)
    return out


def sb3_write_path(path: str | pathlib.Path, suffix: str, verbose: int = 0) -> pathlib.Path:
    """The file SB3's ``open_path`` would write for ``path``, with its warnings: ``suffix`` appended to a path without
    one; a path that is a folder becomes ``<path>_2`` ("Path ... is a folder. Will save instead to ..."); a missing
    parent folder is created ("Path ... does not exist. Will create it."); at ``verbose >= 2`` an existing file is
    reported ("Path ... exists, will overwrite it.").

    :param path: the path given to save.
    :param suffix: the suffix without its dot ("zip", "pkl").
    :param verbose: the verbosity SB3 passes (0 for a model's zip, the model's for a replay buffer).
    """
    path = pathlib.Path(path)
    if path.suffix == "" and suffix:
        path = pathlib.Path(f"{path}.{suffix}")
    while True:
        if path.is_file() and verbose >= 2:
            warnings.warn(f"Path '{path}' exists, will overwrite it.", stacklevel=3)
        if path.is_dir():
            warnings.warn(f"Path '{path}' is a folder. Will save instead to {path}_2", stacklevel=3)
            path = pathlib.Path(f"{path}_2")
            continue
        if not path.parent.exists():
            warnings.warn(f"Path '{path.parent}' does not exist. Will create it.", stacklevel=3)
            path.parent.mkdir(parents=True, exist_ok=True)
        return path


def sb3_read_path(path: str | pathlib.Path, suffixes: tuple[str, ...], verbose: int = 0) -> pathlib.Path:
    """The file SB3's ``open_path`` would read for ``path``: ``path`` if it exists, else ``path`` with a suffix
    appended (the first of ``suffixes`` that exists), with SB3's warning at ``verbose >= 2`` ("Path ... not found.
    Attempting ..."); ``path`` itself when none exists (the caller's open then names it).

    :param path: the path given to load.
    :param suffixes: the suffixes to try, without their dots ("pkl", then "npz" for a replay buffer).
    :param verbose: the verbosity SB3 passes (the model's for a replay buffer).
    """
    path = pathlib.Path(path)
    if path.exists():
        return path
    for suffix in suffixes:
        candidate = pathlib.Path(f"{path}.{suffix}")
        if candidate.exists():
            if verbose >= 2:
                warnings.warn(f"Path '{path}' not found. Attempting {candidate}.", stacklevel=3)
            return candidate
    return path


@contextmanager
def atomic_path(path: str | pathlib.Path, suffix: str) -> Iterator[pathlib.Path]:
    """A partial path to write to, renamed to ``path`` (with ``suffix`` added if it has none) when the block ends
    without error, so that a crash while saving never leaves a truncated file under the final name.

    :param path: the final file.
    :param suffix: the suffix added to a path without one (e.g. ".zip").
    """
    path = pathlib.Path(path)
    if not path.suffix:
        path = path.with_suffix(suffix)
    with atomic_output(path) as partial:  # a unique partial name, fsynced before the rename
        yield partial


def check_rng_state(name: str, value: Any) -> None:
    """A kernel generator's state: 4 uint64 words of xoshiro256**, not all zero (its one fixed point); or a NumPy
    Generator. ValueError naming the attribute.

    :param name: the attribute's name, for the message.
    :param value: the generator state read from the file.
    """
    if isinstance(value, np.random.Generator):
        return
    if not (
        isinstance(value, np.ndarray) and value.dtype == np.uint64 and value.shape == (4,) and value.flags.c_contiguous
    ):
        raise ValueError(
            f"{name}: expected a generator state of 4 uint64 words, got "
            f"{getattr(value, 'dtype', type(value).__name__)} {getattr(value, 'shape', '')}"
        )
    if not value.any():
        raise ValueError(f"{name}: an all-zero xoshiro256** state never changes")
