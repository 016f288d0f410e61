"""The two numba decorators every kernel uses: compiled once per machine (``cache``) and without the GIL (``nogil``),
since no kernel touches a Python object, so that models learning in threads (``sb3-er optimize --n-jobs``) run their
kernels in parallel."""

import numba as nb

#: A kernel called from Python.
kernel = nb.njit(cache=True, nogil=True)
#: A helper inlined into the kernels that call it (no call overhead inside the hot loops).
inline = nb.njit(inline="always", cache=True, nogil=True)
