"""The order to run a pose plan in: small joint moves from one pose to the next.

The cost of going from one joint reading to the next is its largest joint move [rad or
m] (what the slowest joint takes to travel; joint-interpolated moves end together).
Poses are grouped: the touches of one bar or artifact placement stay together (the
operator places the artifact once), and a group may be run forwards or backwards. The
order is

1. inside each group: nearest neighbour from every start, then 2-opt (segment reversals
   that shorten the path), the shortest kept;
2. the groups: the same on the groups' end poses, a reversed stretch of groups running
   each of them backwards;
3. joints whose range spans a full turn or more (a UR's +-360 deg wrist) take, at each
   pose, the turn nearest the previous pose (the first pose: nearest the middle of the
   range): the pose is the same, the move shorter.

Moves are judged with the turn-free distance of such joints, so 1-2 see the moves that
step 3 realises.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .candidates import Candidate

FULL_TURN = 2 * np.pi
TWO_OPT_LIMIT = 1500  # poses above which 2-opt is skipped (its cost grows as n^2)
GROUP_TWO_OPT_LIMIT = 200  # the same for groups (searched pair by pair)


@dataclass(frozen=True)
class Travel:
    """Largest joint move [rad or m] between consecutive poses, in the order found by the
    search (``before``) and in run order (``after``)."""

    before: np.ndarray
    after: np.ndarray

    def __repr__(self) -> str:
        return (f"Travel(median {np.degrees(np.median(self.after)):.1f} deg, was "
                f"{np.degrees(np.median(self.before)):.1f} deg)" if len(self.after)
                else "Travel(single pose)")

    def summary(self) -> str:
        if not len(self.after):
            return "run order: a single pose"
        return (f"run order: largest joint move between consecutive poses median "
                f"{np.degrees(np.median(self.after)):.1f} deg (max "
                f"{np.degrees(np.max(self.after)):.1f}, total "
                f"{np.degrees(np.sum(self.after)):.0f}); unordered: median "
                f"{np.degrees(np.median(self.before)):.1f} deg (max "
                f"{np.degrees(np.max(self.before)):.1f}, total "
                f"{np.degrees(np.sum(self.before)):.0f})")


def largest_moves(Q: np.ndarray) -> np.ndarray:
    """Largest joint move between consecutive rows of ``Q`` (N x dof) [rad or m]."""
    Q = np.atleast_2d(Q)
    return np.max(np.abs(np.diff(Q, axis=0)), axis=1) if len(Q) > 1 else np.zeros(0)


def turning(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """True for joints whose range spans a full turn or more (revolute, unbounded too)."""
    span = np.asarray(upper, float) - np.asarray(lower, float)
    return span >= FULL_TURN - 1e-12


def move_costs(A: np.ndarray, B: np.ndarray, turns: np.ndarray) -> np.ndarray:
    """Largest joint move from every row of ``A`` to every row of ``B`` (len A x len B);
    joints in ``turns`` move the short way round."""
    D = np.abs(A[:, None, :] - B[None, :, :])
    D[..., turns] = np.abs((D[..., turns] + np.pi) % FULL_TURN - np.pi)
    return D.max(axis=2)


def open_path(C: np.ndarray) -> list[int]:
    """An order of the nodes of the symmetric cost matrix ``C`` (n x n) with a short open
    path: nearest neighbour from every start (the best kept), then 2-opt."""
    n = len(C)
    if n <= 2:
        return list(range(n))
    starts = range(n) if n <= 300 else range(0, n, max(1, n // 300))
    # the first of the cheapest paths, as a strict-improvement scan would keep
    best = min((_nearest_neighbour(C, start) for start in starts),
               key=lambda path: float(np.sum(C[path[:-1], path[1:]])))
    return _two_opt(C, best) if n <= TWO_OPT_LIMIT else best


def _nearest_neighbour(C: np.ndarray, start: int) -> list[int]:
    n = len(C)
    visited = np.zeros(n, bool)
    path = [start]
    visited[start] = True
    for _ in range(n - 1):
        row = np.where(visited, np.inf, C[path[-1]])
        nxt = int(np.argmin(row))
        path.append(nxt)
        visited[nxt] = True
    return path


def _two_opt(C: np.ndarray, path: list[int], passes: int = 50) -> list[int]:
    """Reverse ``path[i:j+1]`` while that shortens the open path."""
    p = np.array(path)
    n = len(p)
    for _ in range(passes):
        improved = False
        for i in range(n - 1):
            j = np.arange(i + 1, n)
            # edges (i-1, i) and (j, j+1) become (i-1, j) and (i, j+1); missing ends cost 0
            before = (C[p[i - 1], p[i]] if i > 0 else 0.0) + np.where(
                j < n - 1, C[p[j], p[np.minimum(j + 1, n - 1)]], 0.0)
            after = (C[p[i - 1], p[j]] if i > 0 else 0.0) + np.where(
                j < n - 1, C[p[i], p[np.minimum(j + 1, n - 1)]], 0.0)
            gain = before - after
            k = int(np.argmax(gain))
            if gain[k] > 1e-12:
                p[i:j[k] + 1] = p[i:j[k] + 1][::-1].copy()
                improved = True
        if not improved:
            break
    return list(p)


def order_groups(groups: list[np.ndarray], lower: np.ndarray, upper: np.ndarray
                 ) -> list[tuple[int, np.ndarray]]:
    """Run order of ``groups`` (each k x dof joint rows): ``[(group index, row order)]``."""
    turns = turning(lower, upper)
    inner = [np.array(open_path(move_costs(G, G, turns))) for G in groups]
    heads = np.array([G[o[0]] for G, o in zip(groups, inner)])
    tails = np.array([G[o[-1]] for G, o in zip(groups, inner)])
    n = len(groups)
    # node 2k is group k run forwards (enter at head, leave at tail), 2k+1 backwards
    ends = np.empty((2 * n, 2, heads.shape[1]))
    ends[0::2, 0], ends[0::2, 1] = heads, tails
    ends[1::2, 0], ends[1::2, 1] = tails, heads
    sequence = _group_path(ends, turns)
    return [(node // 2, inner[node // 2] if node % 2 == 0 else inner[node // 2][::-1])
            for node in sequence]


def _group_path(ends: np.ndarray, turns: np.ndarray) -> list[int]:
    """Nodes (group, direction) visiting every group once along a short path: nearest
    neighbour, then 2-opt where reversing a stretch flips each group's direction."""
    n = len(ends) // 2
    if n == 1:
        return [0]
    leave_enter = move_costs(ends[:, 1], ends[:, 0], turns)  # node a's exit to node b's entry
    starts = range(2 * n) if n <= 150 else range(0, 2 * n, max(1, n // 75))
    # the first of the cheapest paths, as a strict-improvement scan would keep
    path = min((_greedy_group_path(leave_enter, start) for start in starts),
               key=lambda path: sum(leave_enter[a, b] for a, b in zip(path[:-1], path[1:])))
    if n > GROUP_TWO_OPT_LIMIT:
        return path
    for _ in range(50):
        improved = False
        for i in range(n - 1):
            for j in range(i + 1, n):
                flipped = [node ^ 1 for node in path[i:j + 1][::-1]]
                old = (leave_enter[path[i - 1], path[i]] if i > 0 else 0.0) + (
                    leave_enter[path[j], path[j + 1]] if j < n - 1 else 0.0)
                new = (leave_enter[path[i - 1], flipped[0]] if i > 0 else 0.0) + (
                    leave_enter[flipped[-1], path[j + 1]] if j < n - 1 else 0.0)
                if new < old - 1e-12:
                    path[i:j + 1] = flipped
                    improved = True
        if not improved:
            break
    return path


def _greedy_group_path(leave_enter: np.ndarray, start: int) -> list[int]:
    """Nodes from ``start``, each step to the cheapest entry of a group not yet visited
    (node ``2g`` runs group ``g`` forwards, ``2g + 1`` backwards)."""
    n = len(leave_enter) // 2
    path = [start]
    used = np.zeros(2 * n, bool)
    used[start & ~1:(start & ~1) + 2] = True
    while len(path) < n:
        nxt = int(np.argmin(np.where(used, np.inf, leave_enter[path[-1]])))
        path.append(nxt)
        used[nxt & ~1:(nxt & ~1) + 2] = True
    return path


def nearest_turns(Q: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """``Q`` (N x dof, run order) with each full-turn joint on the turn nearest the
    previous row (the first row: nearest the middle of the range), within the limits."""
    Q = np.array(Q, float)
    turns = turning(lower, upper)
    middle = np.where(np.isfinite(lower) & np.isfinite(upper), 0.5 * (lower + upper), 0.0)
    previous = middle
    for i in range(len(Q)):
        for j in np.flatnonzero(turns):
            k = np.round((previous[j] - Q[i, j]) / FULL_TURN)
            options = Q[i, j] + FULL_TURN * (k + np.arange(-1, 2))
            options = options[(options >= lower[j]) & (options <= upper[j])]
            if options.size:
                Q[i, j] = options[np.argmin(np.abs(options - previous[j]))]
        previous = Q[i]
    return Q


def order_candidates(candidates, workspace, keep_given: bool = False
                     ) -> tuple[tuple[Candidate, ...], Travel]:
    """``candidates`` in run order (rows inside a placement reordered too), joints on
    their nearest turns, and the travel before and after. ``keep_given``: the order given
    is already a run order (a plan with some poses taken out); it is kept where the search
    finds no shorter one in all."""
    candidates = list(candidates)
    lower, upper = workspace.lower, workspace.upper
    before = largest_moves(np.vstack([c.joints for c in candidates]))
    sequence = order_groups([c.joints for c in candidates], lower, upper)
    ordered = []
    for index, rows in sequence:
        c = candidates[index]
        points = tuple(c.points[r] for r in rows) if c.points else ()
        distance = None if c.distance is None else c.distance[rows]
        ordered.append(Candidate(c.joints[rows], points, c.sockets, distance))
    Q = nearest_turns(np.vstack([c.joints for c in ordered]), lower, upper)
    if keep_given:
        given = nearest_turns(np.vstack([c.joints for c in candidates]), lower, upper)
        if np.sum(largest_moves(given)) <= np.sum(largest_moves(Q)):
            ordered, Q = candidates, given
    out, start = [], 0
    for c in ordered:
        out.append(Candidate(Q[start:start + len(c.joints)], c.points, c.sockets, c.distance))
        start += len(c.joints)
    return tuple(out), Travel(before, largest_moves(Q))
