"""The numba decorators of every kernel and helper.

- ``cache``: compiled once per machine.
- ``nogil``: no kernel touches a Python object, so models learning in threads (``sb3-er optimize --n-jobs``) run their
  kernels in parallel.
- ``_nrt=False``: compiled without numba's reference-counted runtime. The kernels allocate nothing (every array comes
  in from Python, scratch included), so they need no reference counts; with them, every array a helper receives in a
  bundle (a named tuple of up to ten arrays) is counted up and down again at each call, an atomic operation a
  time, which made a replayed update of the walker setup take twice as long as the same arithmetic on plain arrays
  (``benchmarks/replay_throughput.py``). It also makes the rule "no allocation inside a kernel" a compile error: a
  kernel that calls ``np.empty`` or returns a new array no longer compiles.

``inline`` and ``helper`` trade compile time against speed. numba inlines at the level of its own IR and types the
inlined code again at every call site, so helpers inlined into helpers inlined into each phase kernel multiply: with
every helper inlined, a fresh install's first ``ERSigma(...).learn()`` waited minutes for the compiler. Each update
rule is therefore a helper of its own, with its TD error and step inlined into it, which keeps replay within a few per
cent of the all-inlined rate (``benchmarks/compile_time.py`` and ``benchmarks/replay_throughput.py --baseline``; the
measured figures are in the documentation's implementation details).
"""

import numba as nb

#: A kernel called from Python.
kernel = nb.njit(cache=True, nogil=True, _nrt=False)

#: A small helper inlined into its callers by numba (no call inside the hot loops): a few lines of arithmetic, the
#: random numbers, the tile hashing, the TD errors and steps.
inline = nb.njit(inline="always", cache=True, nogil=True, _nrt=False)

#: A helper compiled once as a function of its own and called: each update rule (ER, ER-sigma and their residual
#: forms, with their TD error and step inlined), and the paths off the hot loop (the alpha-bound, the watch's target
#: shift, Sarsa(lambda)'s bounded step, prioritized sweeping's requeue, Dyna's model update).
helper = nb.njit(cache=True, nogil=True, _nrt=False)
