"""Simulated cross-bar touches: the artifact simulator with the bar's four sockets."""

from __future__ import annotations

from ..artifact.simulator import touches
from ..simulation import Generated, Setup


def simulate(setup: Setup) -> Generated:
    """The bar (``setup.bar_length``) placed at random, each arm end touched once."""
    return touches(setup, cross=True)
