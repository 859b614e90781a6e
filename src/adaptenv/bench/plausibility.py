"""Benchmark: the plausibility audit of G's adapted houses, beside random perturbation of the same houses.

For each procedural house (seeded, ``rooms`` rooms) one episode is drawn, the shortest-path expert's
trajectory is analysed by the built-in F, and the house is edited ``steps`` times by the built-in G
and by the failure-mode G (no policy rollout checks: the audit is about where objects end up), and
perturbed at random once (every movable object, the paper's comparison point). Each result is
audited against the house it came from (:func:`adaptenv.adapt.plausibility.audit`). With ``real``
a real ProcTHOR house is adapted the same way on five seeds. Reported per generator: edits
applied, violations per rule, houses with any violation, target instances moved.

Imports sit inside the function: this module is loaded by its ``adaptenv bench`` command.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

NOTES = ["target: zero violations for the built-in and failure-mode G; random perturbation shown for comparison",
         "door_approach: door width x 1 m on each side; group_split: ProcTHOR asset groups; the other rules: "
         "docs/adapt.md"]
GENERATORS = ("builtin", "failure-modes", "random")


def run(*, houses: int = 50, steps: int = 5, seed: int = 0, rooms: int = 5, real: Path | None = None
        ) -> dict[str, Any]:
    """Adapt ``houses`` procedural houses (and ``real`` on 5 seeds) with each generator; audit every result."""
    from adaptenv.adapt.analysis import BuiltinAnalyzer
    from adaptenv.adapt.generators import GenerationContext, make_generator
    from adaptenv.adapt.plausibility import RULES, audit
    from adaptenv.agents.rollout import draw_episode
    from adaptenv.scene.house import load_house
    from adaptenv.scene.procedural import GenerationConfig, generate_house
    from adaptenv.sim.rollout import expert_policy, run_episode
    from adaptenv.sim.world import compile_world

    cfg = GenerationConfig(n_rooms=rooms)
    jobs = [(generate_house(int(np.random.SeedSequence([seed, k]).generate_state(1)[0]), cfg), k)
            for k in range(houses)]
    if real is not None:
        house = load_house(real)
        jobs += [(house, houses + j) for j in range(5)]
    analyzer, expert = BuiltinAnalyzer(), expert_policy()
    gens = {name: make_generator(name) for name in GENERATORS}
    totals = {name: {"edits": 0, "houses with a violation": 0, "targets moved": 0, **dict.fromkeys(RULES, 0)}
              for name in GENERATORS}
    for house, k in jobs:
        world = compile_world(house, f"plausibility-{k}")
        episode = draw_episode(world, np.random.default_rng([seed, k]))
        traj = run_episode(world, episode, expert)
        analysis = analyzer.analyze(traj, world)
        targets = {t.object_id for t in world.instances_of(episode.target_type)}
        for name, gen in gens.items():
            res = gen.generate(house, analysis, steps=steps, rng=np.random.default_rng([seed, k, 1]),
                               context=GenerationContext(episode=episode, trajectory=traj, render=False))
            report = audit(house, res.house)
            row = totals[name]
            row["edits"] += len(res.applied)
            row["houses with a violation"] += int(report.total > 0)
            row["targets moved"] += len(targets & set(report.moved))
            for rule, n in report.counts().items():
                row[rule] += n
    figures: dict[str, Any] = {"houses": houses, "real house runs": 5 if real is not None else 0,
                               "steps per house": steps}
    for name, row in totals.items():
        for key, value in row.items():
            figures[f"{name}: {key}"] = value
    return figures
