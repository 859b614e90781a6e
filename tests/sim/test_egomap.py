"""EgoMap's running count of seen cells agrees with the map it marks, through fresh episodes, resets and copies."""

from __future__ import annotations

import numpy as np

from adaptenv.sim.egomap import SEEN, EgoMap
from adaptenv.sim.spec import N_ACTIONS, N_RAYS, NO_ACTION


def random_obs(rng: np.random.Generator, batch: int, first: bool) -> dict[str, np.ndarray]:
    """Synthetic scans (depth in [0, 1] of the range) and actions; NO_ACTION at an episode's start."""
    return {"depth": rng.uniform(0.05, 1.0, (batch, N_RAYS)).astype(np.float32),
            "semantic": rng.integers(0, 4, (batch, N_RAYS)), "target": rng.integers(0, 4, batch),
            "prev_action": np.full(batch, NO_ACTION) if first else rng.integers(0, N_ACTIONS - 1, batch),
            "collided": rng.integers(0, 2, batch)}


def counted(emap: EgoMap) -> np.ndarray:
    return np.count_nonzero(emap.grid & SEEN, axis=(1, 2))


def test_seen_counts_match_the_marked_cells():
    rng = np.random.default_rng(0)
    emap = EgoMap(5)
    emap.update(random_obs(rng, 5, first=True), np.ones(5, bool))
    last = emap.seen_counts()
    for step in range(20):
        first = np.arange(5) == step % 7  # some agents start new episodes on the way
        emap.update(random_obs(rng, 5, first=False), first)
        seen = emap.seen_counts()
        assert np.array_equal(seen, counted(emap))
        assert (seen[~first] >= last[~first]).all()  # within an episode the count only grows
        last = seen
    emap.reset(np.array([1, 3]))
    assert np.array_equal(emap.seen_counts(), counted(emap)) and (emap.seen_counts()[[1, 3]] == 0).all()
    part = emap.take(np.array([4, 0]))
    assert np.array_equal(part.seen_counts(), emap.seen_counts()[[4, 0]])
    counts = emap.seen_counts()
    counts[:] = -1  # a copy: the map's own count is untouched
    assert np.array_equal(emap.seen_counts(), counted(emap))
