"""Replay the learned G's half of ``adaptenv bench adapt`` house by house, to compare two commits' outcomes.

    PYTHONPATH=TREE/src NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 python replay_learned.py OUT.jsonl [HOUSES]

Draws the benchmark's houses and solved episodes (procedural, 5 rooms, seed 0, ``pretrained`` agent, 10 tries) and
makes the learned G's 5 edits with the benchmark's seeds; one row per adapted house (``k``, success after on the
episode's own draw, steps, the edits) is appended to OUT.jsonl, and a rerun skips the houses already there. The agent
seeds its sampler per episode, so leaving out the built-in G's half does not change these rollouts.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from adaptenv.adapt.analysis import BuiltinAnalyzer
from adaptenv.adapt.generators import make_generator
from adaptenv.adapt.step import adapt_scene
from adaptenv.agents.network import configure_torch
from adaptenv.agents.registry import resolve_policy
from adaptenv.agents.rollout import find_solved_episode
from adaptenv.scene.procedural import GenerationConfig, generate_house
from adaptenv.sim.world import compile_world


def main(out: Path, houses: int = 50, seed: int = 0) -> None:
    """Append one row per adapted house not yet in ``out``."""
    configure_torch()
    done = {json.loads(line)["k"] for line in out.open()} if out.exists() else set()
    agent, cfg = resolve_policy("pretrained", seed=seed), GenerationConfig(n_rooms=5)
    learned, analyzer = make_generator("learned"), BuiltinAnalyzer()
    k = n = 0
    while n < houses and k < 3 * houses:
        house = generate_house(int(np.random.SeedSequence([seed, k]).generate_state(1)[0]), cfg)
        k += 1
        found = find_solved_episode(compile_world(house, f"bench-{k}"), agent, np.random.default_rng([seed, k]), tries=10)
        if found is None:
            continue
        n += 1
        if k in done:
            continue
        episode, before = found
        res = adapt_scene(house, episode, policy=agent, analyzer=analyzer, generator=learned, steps=5,
                          rng=np.random.default_rng([seed, k, 1]), before=before, name=f"bench-{k}")
        row = {"k": k, "succ": bool(res.after.metrics.success), "steps": len(res.after.steps),
               "edits": [str(e) for e in res.generation.applied]}
        with out.open("a", encoding="utf-8") as f:
            f.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main(Path(sys.argv[1]), *(int(a) for a in sys.argv[2:3]))
