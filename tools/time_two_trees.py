"""Time the map-reading agent's training and evaluation in two source trees, alternately.

    python tools/time_two_trees.py BEFORE_SRC AFTER_SRC [ROUNDS] [--figures map,loop]

BEFORE_SRC and AFTER_SRC are ``src`` folders of two checkouts (for example after ``git worktree add
/tmp/before COMMIT``, ``/tmp/before/src``). Each round runs one fresh process per tree, in alternating
order; each process warms what it times once, untimed. Figures:

- ``map``: ``train`` with the map recipe (``adaptenv.bench.train.MAP_RECIPE``, 3 iterations, every
  core) by the run's own clock over its training loop, and the map explorer's labelling
  (``adaptenv.bench.teachers.bench_labelling``), frames/s;
- ``loop``: what one worker of ``adaptenv experiment`` runs, on one torch thread: the loop's PPO
  fine-tuning (``adaptenv.bench.train.LOOP_PPO``, 3 x 8,192 frames, frames/s) and a held-out
  evaluation job (250 ``val-far`` episodes of ``pretrained-ppo`` on refilled slots, seconds), with a
  digest of the fine-tuned weights and the episodes' outcomes (both trees should give the same). Set
  ``NUMBA_NUM_THREADS=1`` to time it as the experiment's workers run.

Prints each round and, as JSON, the medians per tree and the medians of the paired ratios (after /
before), with the load average before and after: quote them only when nothing else ran.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys

# The timing snippets run in BEFORE_SRC too, so they use only what both trees have (TrainConfig, train, train_ppo,
# bench_labelling, MAP_RECIPE, LOOP_PPO), not a helper that only the newer tree would define.
MAP = """
from adaptenv.agents.config import TrainConfig
from adaptenv.agents.train import train
from adaptenv.bench.teachers import bench_labelling
from adaptenv.bench.train import MAP_RECIPE

worlds = load_house_set(HOUSES).worlds
block = TrainConfig().num_envs * TrainConfig().rollout_steps


def loop_fps(n):
    cfg = TrainConfig(frames=n * block, output="", run_dir="", eval_every=0, final_eval_episodes=1,
                      calibrate_episodes=0, progress=False, tensorboard=False, **MAP_RECIPE)
    rows = train(cfg, worlds=worlds).rows
    return n * block / max(r["wall_time"] for r in rows if "losses/loss" in r)


loop_fps(1)
figures["map_recipe_frames_per_s"] = loop_fps(3)
figures["map_explorer_labelling_frames_per_s"] = bench_labelling(HOUSES)["map_explorer_fps"]
"""

LOOP = """
import hashlib
import torch
from adaptenv.agents.config import PPOConfig
from adaptenv.agents.evaluate import run_episodes, sample_episodes
from adaptenv.agents.ppo import train_ppo
from adaptenv.agents.registry import resolve_policy
from adaptenv.bench.train import LOOP_PPO
from adaptenv.curriculum.jobs import EVAL_BATCH, EVAL_CHUNK, heldout_set

torch.set_num_threads(1)
worlds = load_house_set(HOUSES).worlds
block = PPOConfig().num_envs * PPOConfig().rollout_steps


def ppo_fps(n):
    cfg = PPOConfig(frames=n * block, output="", run_dir="", eval_every=0, final_eval_episodes=0,
                    calibrate_episodes=0, progress=False, tensorboard=False, value_warmup_iters=0, **LOOP_PPO)
    start = time.perf_counter()
    net = train_ppo(cfg, worlds=worlds).net
    seconds = time.perf_counter() - start
    fingerprint.update(b"".join(v.numpy().tobytes() for v in net.state_dict().values()))
    return n * block / seconds


fingerprint = hashlib.sha1()  # the fine-tuned weights, then the episodes
ppo_fps(1)
figures["ppo_frames_per_s"] = ppo_fps(3)
suite = heldout_set("suite:val-far").worlds
policy = resolve_policy("pretrained-ppo")
eps = sample_episodes(suite, EVAL_CHUNK, 0)
run_episodes(suite, eps[:EVAL_BATCH], policy, batch=EVAL_BATCH)
start = time.perf_counter()
results, _ = run_episodes(suite, eps, policy, batch=EVAL_BATCH)
figures["eval_job_seconds"] = time.perf_counter() - start
fingerprint.update(repr([(r.success, r.steps, round(r.spl, 9)) for r in results]).encode())
digest = fingerprint.hexdigest()
"""

HEAD = """
import json, time
from adaptenv.agents.houses import load_house_set
HOUSES = {houses!r}
figures, digest = {{}}, None
"""
TAIL = """
print(json.dumps({"figures": figures, "digest": digest}))
"""


def run_child(src: str, code: str) -> dict:
    """The figures of one fresh process importing adaptenv from ``src``."""
    env = {**os.environ, "PYTHONPATH": os.path.abspath(src)}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    if out.returncode:
        raise SystemExit(f"{src}: the timing process failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before")
    parser.add_argument("after")
    parser.add_argument("rounds", nargs="?", type=int, default=3)
    parser.add_argument("--figures", default="map", help="comma-separated: map, loop (see the module docstring)")
    parser.add_argument("--houses", default="preset:pretrain-train")
    args = parser.parse_args()
    parts = {"map": MAP, "loop": LOOP}
    chosen = [f.strip() for f in args.figures.split(",") if f.strip()]
    if not chosen or any(f not in parts for f in chosen):
        parser.error(f"--figures {args.figures!r}: choose among {', '.join(parts)}, comma-separated")
    for src in (args.before, args.after):
        if not os.path.isdir(os.path.join(src, "adaptenv")):
            parser.error(f"{src}: no adaptenv package here; pass the src folder of a checkout")
    code = HEAD.format(houses=args.houses) + "".join(parts[f] for f in chosen) + TAIL
    load_before = os.getloadavg()[0]
    runs: dict[str, list[dict]] = {"before": [], "after": []}
    for k in range(args.rounds):
        for name in (("before", "after") if k % 2 == 0 else ("after", "before")):
            runs[name].append(run_child(getattr(args, name), code))
            print(f"round {k}: {name} {runs[name][-1]}", file=sys.stderr, flush=True)
    keys = runs["before"][0]["figures"].keys()
    report: dict = {name: {key: statistics.median(r["figures"][key] for r in rs) for key in keys}
                    for name, rs in runs.items()}
    report["after_over_before"] = {key: statistics.median(a["figures"][key] / b["figures"][key] for a, b in
                                                          zip(runs["after"], runs["before"], strict=True))
                                   for key in keys}
    digests = {r["digest"] for rs in runs.values() for r in rs}
    report.update(rounds=args.rounds, houses=args.houses, figures=chosen,
                  numba_num_threads=os.environ.get("NUMBA_NUM_THREADS", "default"),
                  same_results=None if digests == {None} else len(digests) == 1,
                  load_average_1min_before=load_before, load_average_1min_after=os.getloadavg()[0])
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
