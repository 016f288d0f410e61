"""The two numba decorators every kernel uses.

- ``cache``: compiled once per machine.
- ``nogil``: no kernel touches a Python object, so models learning in threads (``sb3-er optimize --n-jobs``) run their
  kernels in parallel.
- ``_nrt=False``: compiled without numba's reference-counted runtime. The kernels allocate nothing (every array comes
  in from Python, scratch included), so they need no reference counts; with them, every array a helper receives in a
  bundle (a named tuple of up to ten arrays) is counted up and down again at each call, an atomic operation a
  time, which made a replayed update of the walker setup take twice as long as the same arithmetic on plain arrays
  (``benchmarks/replay_throughput.py``). It also makes the rule "no allocation inside a kernel" a compile error: a
  kernel that calls ``np.empty`` or returns a new array no longer compiles.
"""

import numba as nb

#: A kernel called from Python.
kernel = nb.njit(cache=True, nogil=True, _nrt=False)

#: A helper inlined into the kernels that call it (no call overhead inside the hot loops).
inline = nb.njit(inline="always", cache=True, nogil=True, _nrt=False)
