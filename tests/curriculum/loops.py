"""Small closed-loop settings the curriculum tests share, and what a run measures."""

from __future__ import annotations

from pathlib import Path

import pytest

from adaptenv.curriculum.loop import LoopConfig

SHARES_RUNS = pytest.mark.xdist_group("shared-loop-runs")
"""On the tests that read a run another test also reads (conftest.py's ``loop_run``): ``make test`` runs them in
one worker (``--dist loadgroup``), so each shared run is made once, not once per worker."""


def tiny_config(policy: Path, method: str, **kw) -> LoopConfig:
    """Two iterations on the tiny preset with the smallest budgets that still exercise every stage (fine-tuning by
    DAgger, whose smallest budget is smaller than PPO's 128-step rollout; test_loop.py runs the default, PPO)."""
    base = dict(method=method, policy=str(policy), houses="preset:tiny", heldout={"tiny": "preset:tiny"},
                finetune_algo="dagger", finetune_max_steps=300, finetune_min_start=0.0,
                iterations=2, scenes_per_iteration=2, edit_steps=1, finetune_frames=512, finetune_envs=16,
                heldout_episodes=3, gallery=1, buffer_capacity=4, diagnose_episodes=1)
    return LoopConfig(**{**base, **kw})


def figures(records) -> list[tuple]:
    """Everything a run measures, without wall times."""
    return [(r.iteration, r.env_steps, r.grad_updates, r.edits,
             {k: (v.success, round(v.spl, 9), v.collisions) for k, v in r.heldout.items()},
             (r.train.success, round(r.train.spl, 9)) if r.train else None) for r in records]
