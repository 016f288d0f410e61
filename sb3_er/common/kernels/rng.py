"""Seeded random numbers for the kernels: xoshiro256** states passed in as 4-word arrays, and the splitmix64 mix that
also hashes tiles and initial weights. A NumPy Generator would cost about 20 us per kernel call to unbox; a state array
costs nothing, and each (seed, stream) pair gives an independent generator."""

import numpy as np

from sb3_er.common.kernels._jit import inline

RNG_STREAM_ACTIONS, RNG_STREAM_REPLAY, RNG_STREAM_PREDICT = 0, 1, 2
RNG_STREAM_PLANNING = 100  # Dyna's planning picks

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)


def new_rng_state(seed=None, stream: int = RNG_STREAM_ACTIONS) -> np.ndarray:
    """A seeded xoshiro256** state for the kernels; each stream of one seed is independent (None: fresh entropy).

    :param seed: the seed (default None: fresh entropy).
    :param stream: the stream of that seed (RNG_STREAM_*; default the actions' stream).
    """
    return np.random.SeedSequence(seed, spawn_key=(stream,)).generate_state(4, dtype=np.uint64)


@inline
def mix64(h):
    """The splitmix64 finaliser: a bijective 64-bit mix.

    :param h: a uint64.
    """
    h ^= h >> np.uint64(30)
    h *= _MIX1
    h ^= h >> np.uint64(27)
    h *= _MIX2
    h ^= h >> np.uint64(31)
    return h


@inline
def _rotl(x, k):
    return (x << np.uint64(k)) | (x >> np.uint64(64 - k))


@inline
def random_uint64(state):
    """Next output of xoshiro256** (Blackman and Vigna, 2018); advances state in place.

    :param state: a xoshiro256** state (4 uint64), advanced in place.
    """
    result = _rotl(state[1] * np.uint64(5), 7) * np.uint64(9)
    t = state[1] << np.uint64(17)
    state[2] ^= state[0]
    state[3] ^= state[1]
    state[1] ^= state[2]
    state[0] ^= state[3]
    state[2] ^= t
    state[3] = _rotl(state[3], 45)
    return result


@inline
def random_float(state):
    """Uniform in [0, 1) with 53 random bits.

    :param state: a xoshiro256** state (4 uint64), advanced in place.
    """
    return np.float64(random_uint64(state) >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@inline
def random_integer(state, n):
    """Uniform in {0, ..., n-1}.

    :param state: a xoshiro256** state (4 uint64), advanced in place.
    :param n: the number of values, at least 1.
    """
    return np.int64(random_float(state) * n)
