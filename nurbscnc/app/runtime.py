"""Process tuning of a command: BLAS threads, the allocator's reuse of freed memory, and the
cycle collector around the planning.

Settings of the process, not of any stage: the stages and their results are the same with
or without them; they change where the time and the memory go.
"""

from __future__ import annotations

import contextlib
import gc
import os

#: glibc's ``mallopt`` parameters (malloc.h) and the values set by :func:`reuse_freed_memory`.
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD, M_ARENA_MAX = -1, -3, -8
MMAP_THRESHOLD_BYTES = 32 * 2**20  # glibc's own ceiling for its sliding threshold
TRIM_THRESHOLD_BYTES = 2**30


def single_blas_thread() -> None:
    """One BLAS thread unless the user set it: the commands' vector operations are far too
    small for threads, and OpenBLAS's idle threads spin on the other core (measured: a
    1,000,000-line ``run`` spent 15.5 s of CPU instead of 11.8, tort's ``plan`` 5.5 s instead
    of 3.6, and both took longer). Read when numpy is first imported, which the commands do
    lazily, after this."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def reuse_freed_memory() -> None:
    """Let glibc's malloc reuse freed blocks below 32 MB instead of giving them back to the
    kernel and faulting fresh pages in for the next one.

    The commands allocate and free the same large numpy temporaries window after window.
    By default glibc trims the top of its heap when more than twice its sliding mmap
    threshold is free, so the next allocation of that size faults every page in again
    (measured: the 200,000-line spiral's ``run`` spent 0.4–0.5 s of 2.5 s in the kernel, on
    215,000 page faults). With the threshold fixed at glibc's ceiling (32 MB) and trimming
    above 1 GB: 113,000 faults, 0.25 s in the kernel, 1.3 % more peak memory. Blocks of 32 MB
    and more are still mapped and unmapped on their own. One arena for every thread: the
    thread that makes ``run``'s points while the output is written
    (:mod:`nurbscnc.output.background`) then reuses the blocks the planner freed instead of
    growing an arena of its own (200,000-line spiral: 38 MB more peak memory without).
    Not glibc (macOS, musl): nothing."""
    try:
        if not os.confstr("CS_GNU_LIBC_VERSION"):
            return
        import ctypes

        libc = ctypes.CDLL(None)
        libc.mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)
        libc.mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES)
        libc.mallopt(M_ARENA_MAX, 1)
    except (ValueError, OSError, AttributeError):  # no confstr name, no libc, no mallopt
        return


def tune_process() -> None:
    """The settings every command starts with: :func:`single_blas_thread`,
    :func:`reuse_freed_memory`."""
    single_blas_thread()
    reuse_freed_memory()


@contextlib.contextmanager
def frozen_objects():
    """The objects alive now (an interpreted program's, the modules') are left out of the
    cycle collector's passes while the block runs, and thawed after, so nothing stays exempt.

    A CAM program's 200,000 lines are 600,000 objects that live until the plan is made: the
    collector's full passes need not walk them (measured on the 200k spiral: 0.19 s of
    collections, 0.12 s of it four full passes)."""
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()
