"""Connected components of a graph given by its edges, vectorised with numpy (no scipy in the model)."""

from __future__ import annotations

import numpy as np

__all__ = ["parity_roots", "component_labels", "count_components"]


def parity_roots(n: int, a: np.ndarray, b: np.ndarray, differ: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(root, parity)`` of ``n`` nodes joined by the edges ``(a[k], b[k])``, each edge saying whether its two
    nodes differ (``differ[k]``): each node's component's smallest node, and whether the node differs from it,
    as the edges of a spanning tree say (an edge that disagrees with the tree is not looked at: the caller
    checks). Vectorised hooking and pointer jumping: each round follows every pointer to its root, carrying
    the parity along, then hooks each root that an edge joins to a smaller root under the smallest such; a
    round that finds no edge between two roots ends it. Every pointer runs to a smaller node, so there is no
    cycle, and the rounds grow with the logarithm of a component's span on a mesh, not with its diameter."""
    label = np.arange(n)
    parity = np.zeros(n, dtype=bool)
    while True:
        while True:  # to the roots, the parity along
            jumped = label[label]
            if np.array_equal(jumped, label):
                break
            parity = parity ^ parity[label]
            label = jumped
        ra, rb = label[a], label[b]
        apart = ra != rb
        if not apart.any():
            return label, parity
        # each root joined to a smaller one hooks under the smallest, by one of the edges that join them
        high, low = np.maximum(ra, rb)[apart], np.minimum(ra, rb)[apart]
        implied = (parity[a] ^ parity[b] ^ differ)[apart]  # whether the two roots differ, by this edge
        order = np.lexsort((low, high))
        high, low, implied = high[order], low[order], implied[order]
        first = np.r_[True, high[1:] != high[:-1]]
        label[high[first]] = low[first]
        parity[high[first]] = implied[first]


def component_labels(n: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The connected component of each of ``n`` nodes joined by the undirected edges ``(a[k], b[k])``: the
    smallest node of its component (so ``len(np.unique(labels))`` counts the components); see
    :func:`parity_roots`."""
    a = np.asarray(a, dtype=np.int64)
    return parity_roots(n, a, np.asarray(b, dtype=np.int64), np.zeros(len(a), dtype=bool))[0]


def count_components(n: int, a: np.ndarray, b: np.ndarray) -> int:
    """How many connected components ``n`` nodes joined by the edges ``(a[k], b[k])`` form (a node on no edge
    is one)."""
    return int(np.count_nonzero(component_labels(n, a, b) == np.arange(n)))
