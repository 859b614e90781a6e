"""Benchmark: the built-in G on procedural houses the policy solves.

For each procedural house (seeded, ``rooms`` rooms): draw episodes until the policy succeeds
(houses where it never does within ``tries`` draws are skipped), analyse the successful episode
with the built-in F, make ``steps`` built-in edits (candidates checked with the policy), then
re-run the policy from the same start on the same target. Reported:

- agent success and SPL before and after on the adapted houses (target: at least 30 points lower
  success after; before is 100% by construction);
- expert success after (must stay 100%);
- realism of the built-in result versus a random perturbation of the same house (the paper's
  claim: built-in scores higher), and the plausibility audit's violations of each (summed over houses);
- validated edits per second (placement + validation, no rollouts) from
  :mod:`adaptenv.bench.adapt_edits` (target: at least 1,000 on one core for a 5-room house), and
  the wall time per adapted house;
- the learned G (``--generator learned``, the shipped scorer) on the same episodes: its success drop,
  audit violations and wall time per adapted house beside the built-in G's;
- each G's success drop on ``EPISODE_FRESH_DRAWS`` (8) fresh action draws of the episode (the same start and target, new
  sampling seeds): the built-in G's rollout checks include the episode's own draw, and these no G rolled out.

Imports sit inside the functions: this module is loaded by its ``adaptenv bench`` command, and a
benchmark loads what it measures (torch, numba, ray) only when it runs.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

NOTES = ["targets: success drop >= 30 points; expert success after = 100%; realism builtin > random; "
         ">= 1,000 validated edits/s",
         "before = 100% success by construction (only houses the policy solves are adapted)"]


def run(*, houses: int = 50, steps: int = 5, policy: str = "pretrained-scan", seed: int = 0, rooms: int = 5,
        tries: int = 10, max_houses: int | None = None) -> dict[str, Any]:
    """Adapt ``houses`` solved houses and return the figures (see the module docstring)."""
    from adaptenv.adapt.analysis import BuiltinAnalyzer
    from adaptenv.adapt.generators import GenerationContext, make_generator
    from adaptenv.adapt.generators.builtin import BuiltinGenerator
    from adaptenv.adapt.generators.random_perturbation import RandomPerturbation
    from adaptenv.adapt.objectives import realism_score
    from adaptenv.adapt.plausibility import audit
    from adaptenv.adapt.step import adapt_scene
    from adaptenv.adapt.target import EPISODE_FRESH_DRAWS as FRESH
    from adaptenv.adapt.target import fresh_measurement
    from adaptenv.agents.policy import ExpertPolicy
    from adaptenv.agents.registry import resolve_policy
    from adaptenv.agents.rollout import find_solved_episode, rollout
    from adaptenv.bench.adapt_edits import run as run_edits
    from adaptenv.scene.procedural import GenerationConfig, generate_house
    from adaptenv.sim.world import compile_world

    agent = resolve_policy(policy, seed=seed)
    expert = ExpertPolicy()
    cfg = GenerationConfig(n_rooms=rooms)
    analyzer, builtin, random_g = BuiltinAnalyzer(), BuiltinGenerator(), RandomPerturbation()
    learned = make_generator("learned")
    rows: list[dict[str, Any]] = []
    skipped = 0
    t_adapt = t_learned = 0.0
    limit = max_houses if max_houses is not None else houses * 3
    k = 0
    while len(rows) < houses and k < limit:
        house = generate_house(int(np.random.SeedSequence([seed, k]).generate_state(1)[0]), cfg)
        k += 1
        world = compile_world(house, f"bench-{k}")
        rng = np.random.default_rng([seed, k])
        found = find_solved_episode(world, agent, rng, tries=tries)
        if found is None:
            skipped += 1
            continue
        episode, before = found
        t = time.perf_counter()
        res = adapt_scene(house, episode, policy=agent, analyzer=analyzer, generator=builtin, steps=steps,
                          rng=np.random.default_rng([seed, k, 1]), before=before, name=f"bench-{k}")
        t_adapt += time.perf_counter() - t
        exp = rollout(res.world, episode, expert)
        t = time.perf_counter()
        lrn = adapt_scene(house, episode, policy=agent, analyzer=analyzer, generator=learned, steps=steps,
                          rng=np.random.default_rng([seed, k, 1]), before=before, name=f"bench-{k}")
        t_learned += time.perf_counter() - t
        fresh = [fresh_measurement(w, [episode], agent, FRESH).success for w in (world, res.world, lrn.world)]
        rnd = random_g.generate(house, res.analysis, steps=steps,
                                context=GenerationContext(episode=episode, render=False),
                                rng=np.random.default_rng([seed, k, 2]))
        rows.append({
            "success_before": before.metrics.success, "spl_before": before.metrics.spl,
            "success_after": res.after.metrics.success, "spl_after": res.after.metrics.spl,
            "expert_after": exp.metrics.success, "edits": res.edits_applied, "verified": res.edits_verified,
            "valid": res.valid,
            "realism_original": realism_score(house, house), "realism_builtin": realism_score(res.house, house),
            "realism_random": realism_score(rnd.house, house),
            "violations_builtin": audit(house, res.house).total, "violations_random": audit(house, rnd.house).total,
            "success_after_learned": lrn.after.metrics.success, "violations_learned": audit(house, lrn.house).total,
            "fresh_before": fresh[0], "fresh_after": fresh[1], "fresh_after_learned": fresh[2],
        })
    n = len(rows)

    def mean(key: str) -> float:
        vals = [float(r[key]) for r in rows if r[key] is not None]
        return float(np.mean(vals)) if vals else float("nan")

    edits = run_edits(2000, seed)
    figures: dict[str, Any] = {
        "policy": policy, "houses adapted": n, "houses skipped (never solved)": skipped, "steps per house": steps,
        "edits applied (mean)": mean("edits"), "edits verified (mean)": mean("verified"),
        "agent success before": mean("success_before"), "agent success after": mean("success_after"),
        "success drop (points)": 100.0 * (mean("success_before") - mean("success_after")),
        f"agent success on {FRESH} fresh draws before": mean("fresh_before"),
        f"success drop on {FRESH} fresh draws (points)": 100.0 * (mean("fresh_before") - mean("fresh_after")),
        "agent SPL before": mean("spl_before"), "agent SPL after": mean("spl_after"),
        "expert success after": mean("expert_after"),
        "realism original": mean("realism_original"), "realism builtin": mean("realism_builtin"), "realism random": mean("realism_random"),
        "plausibility violations builtin (sum)": int(sum(r["violations_builtin"] for r in rows)),
        "plausibility violations random (sum)": int(sum(r["violations_random"] for r in rows)),
        "validated edits per s": edits["validated edits per s"],
        "valid after final validation": mean("valid"),
        "adapt s per house (adapt_scene: F, G with rollout checks, validation, after-rollout)": t_adapt / max(n, 1),
        "learned G: agent success after": mean("success_after_learned"),
        "learned G: success drop (points)": 100.0 * (mean("success_before") - mean("success_after_learned")),
        f"learned G: success drop on {FRESH} fresh draws (points)":
            100.0 * (mean("fresh_before") - mean("fresh_after_learned")),
        "learned G: plausibility violations (sum)": int(sum(r["violations_learned"] for r in rows)),
        "learned G: adapt s per house (scored proposals, their route objectives, validation, after-rollout)": t_learned / max(n, 1),
    }
    return figures
