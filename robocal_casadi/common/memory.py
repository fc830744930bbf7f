"""Freed memory handed back to the system between the large steps of a job.

glibc's allocator keeps memory a program has freed for reuse; after a large temporary
array it raises its threshold for mapping allocations on their own, so later arrays of
up to 32 MiB come from the shared heap and stay resident once freed. Before a step that
allocates a lot (a diagnosis round's stacked Jacobian, the report's figures) the job
returns the heap's free pages (``malloc_trim``), so the process's peak resident size is
what the step holds plus what is live, not plus what was freed before. Elsewhere (another
C library, another system) this does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools


@functools.cache
def _trim():
    """glibc's ``malloc_trim``, or None where there is none."""
    name = ctypes.util.find_library("c")
    if name is None:
        return None
    try:
        return getattr(ctypes.CDLL(name), "malloc_trim", None)
    except OSError:
        return None


def release_freed() -> None:
    """Return the C heap's free pages to the system (a no-op without glibc)."""
    trim = _trim()
    if trim is not None:
        trim(0)
