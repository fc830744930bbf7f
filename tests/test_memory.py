"""Freed heap memory goes back to the system (glibc), and the call is harmless elsewhere."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from robocal_casadi.common import memory

STATM = Path("/proc/self/statm")


def _resident() -> int:
    """This process's resident size [bytes]."""
    return int(STATM.read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE")


@pytest.mark.skipif(memory._trim() is None or not STATM.is_file(),
                    reason="needs glibc's malloc_trim and /proc")
def test_freed_heap_pages_are_returned():
    # 80 MB in blocks of 2 kB (allocated on the C heap, not mapped one by one), every
    # tenth one kept so that the freed ones cannot be returned by shrinking the heap from
    # its top: only the whole pages inside the runs of nine freed blocks can go back.
    blocks = [bytes(2000) for _ in range(40_000)]
    kept = blocks[::10]
    del blocks
    before = _resident()
    memory.release_freed()
    after = _resident()
    assert len(kept) == 4_000
    # 72 MB freed in runs of about 18 kB, each holding at least three whole 4 kB pages:
    # at least 12 of every 18 kB, over 40 MB in all (20 MB leaves room for the runs
    # the allocator put elsewhere).
    assert before - after > 20e6


def test_release_is_harmless_without_anything_freed():
    memory.release_freed()
    memory.release_freed()


@pytest.mark.parametrize("rows", [1, 2047, 2048, 5001])
def test_the_screening_stack_over_the_jacobian_s_own_buffer_holds_the_same_values(rows):
    """The diagnosis stacks ``[J[:, columns], r]`` over ``J``'s own memory when it owns
    ``J``: every value is the one a fresh copy holds, in blocks that end anywhere, and the
    stack lives in ``J``'s buffer (no second matrix of that size)."""
    import numpy as np

    from robocal_casadi.calibration.diagnosis import _stacked

    rng = np.random.default_rng(rows)
    J = rng.normal(size=(rows, 9))
    r = rng.normal(size=rows)
    columns = [7, 0, 3, 8]
    expected = np.column_stack([J[:, columns], r])
    copied = _stacked(J.copy(), columns, r, owned=False)
    buffer = J.copy()
    stacked = _stacked(buffer, columns, r, owned=True)
    np.testing.assert_array_equal(copied, expected)
    np.testing.assert_array_equal(stacked, expected)
    assert np.shares_memory(stacked, buffer)
    # Wider than the Jacobian (every column and more): a copy, the Jacobian untouched.
    narrow = J[:, :2].copy()
    wide = _stacked(narrow, [0, 1, 0], r, owned=True)
    assert not np.shares_memory(wide, narrow)
    np.testing.assert_array_equal(narrow, J[:, :2])
