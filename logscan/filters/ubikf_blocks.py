"""The UBIKF run block by block: an interval model whose states fall into independent blocks is
filtered as one small model per block (docs/algorithms.md section 2.1).

Two states are in one block when any of A_m, A_r, Q+ or P0 couples them, when one measurement row
(C_m or C_r) reads both, or when R+ couples two rows that read them. Then every matrix of the
recursion keeps that block structure: P+ is block diagonal (each term of the weighted bound is),
a gain column of a row lives in its row's block, and so does every generator of the state set. The
input matrix couples nothing (B u enters the centre and, through B_r |u|, each state's own box).
Filtering each block alone is exact up to the weights of the weighted bound, which are then chosen
per block (any positive weights give a sound bound, docs/algorithms.md section 2), and costs the sum
of the blocks' sizes squared instead of the whole size squared: the hover quadcopter's 12 states
are four chains (z; x, pitch; y, roll; yaw) of at most four states.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Block(NamedTuple):
    """One block: its states and its measurement rows (sorted global indices)."""

    states: np.ndarray  # (n_b,) int64
    rows: np.ndarray  # (m_b,) int64


def state_blocks(A_m, A_r, C_m, C_r, Q, R, P0) -> list[Block]:
    """The blocks of an interval model (see the module docstring), ordered by their first state.
    A row that reads no state joins the block of state 0."""
    n = A_m.shape[0]
    parent = np.arange(n)

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = int(parent[i])
        return i

    def union(i: int, j: int) -> None:
        a, b = find(i), find(j)
        if a != b:
            parent[max(a, b)] = min(a, b)

    for M in (A_m, A_r, Q, P0):
        for i, j in np.argwhere(M != 0):
            union(int(i), int(j))
    reads = (C_m != 0) | (C_r != 0)
    first = [int(np.flatnonzero(r)[0]) if r.any() else 0 for r in reads]
    for a, row in enumerate(reads):
        for j in np.flatnonzero(row):
            union(first[a], int(j))
    for a, b in np.argwhere(R != 0):
        union(first[a], first[b])
    roots = np.array([find(i) for i in range(n)])
    row_roots = np.array([roots[f] for f in first], dtype=np.int64)
    return [
        Block(np.flatnonzero(roots == r).astype(np.int64), np.flatnonzero(row_roots == r).astype(np.int64))
        for r in sorted(set(roots.tolist()))
    ]


def block_groups(rows: np.ndarray, offsets: np.ndarray, sizes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(offsets, sizes) of every measurement group within a block's rows (a group with no row
    there: size 0). The rows are sorted and a group's rows are contiguous, so they stay so."""
    sub_sizes = np.array([np.count_nonzero((rows >= o) & (rows < o + s)) for o, s in zip(offsets, sizes)])
    sub_offsets = np.concatenate([[0], np.cumsum(sub_sizes)[:-1]]).astype(np.int64)
    return sub_offsets, sub_sizes.astype(np.int64)


def usable_groups(z: np.ndarray, fresh: np.ndarray, offsets: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """(N, G) bool: group g updates at step k (a fresh sample, every value of it finite), judged on
    the whole group, so that every block agrees."""
    usable = np.asarray(fresh, dtype=np.bool_).copy()
    for g, (o, s) in enumerate(zip(offsets, sizes)):
        usable[:, g] &= np.isfinite(z[:, o : o + s]).all(axis=1)
    return usable
