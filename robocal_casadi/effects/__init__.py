"""Effects the DH model lacks, each a small ``Effect`` subclass."""

from .base import Effect, RowContext

__all__ = ["Effect", "RowContext"]
