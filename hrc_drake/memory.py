"""Giving freed memory back to the operating system.

numpy's arrays of a few MB come from the C heap once glibc has raised its mmap threshold (it
does after freeing a large block); many short-lived batches then leave the heap fragmented, and
the process keeps their pages after the arrays are gone. At 10^6 states that is about 100 MB
that a later peak (writing a policy file) stacks on. `malloc_trim` returns free pages anywhere
in the heap.
"""

from __future__ import annotations

import ctypes
import ctypes.util
from functools import cache


@cache
def _libc():
    name = ctypes.util.find_library("c")
    if name is None:
        return None
    try:
        libc = ctypes.CDLL(name)
        return libc if hasattr(libc, "malloc_trim") else None  # glibc only
    except OSError:
        return None


def give_back_free_memory() -> None:
    """Return the C heap's free pages to the operating system (glibc); elsewhere, nothing."""
    libc = _libc()
    if libc is not None:
        libc.malloc_trim(0)
