"""Throwaway measurement kept as the record of docs/BENCHMARKS.md, "Where the map learner's gradient step goes"; see the .txt beside it."""
import statistics

import torch

from adaptenv.agents import network
from adaptenv.agents.config import TrainConfig
from adaptenv.agents.houses import load_house_set
from adaptenv.agents.train import train
from adaptenv.bench.train import MAP_RECIPE

worlds = load_house_set("preset:pretrain-train").worlds
block = 256 * 64
orig = network.NavNet.step
def bf16_step(self, obs, done, h):
    with torch.autocast("cpu", dtype=torch.bfloat16):
        logits, h = orig(self, obs, done, h)
    return logits.float(), h.float()
def one(bf, n):
    network.NavNet.step = bf16_step if bf else orig
    cfg = TrainConfig(frames=n * block, output="", run_dir="", eval_every=0, final_eval_episodes=1,
                      calibrate_episodes=0, progress=False, tensorboard=False, **MAP_RECIPE)
    result = train(cfg, worlds=worlds)
    rows = [r for r in result.rows if "losses/loss" in r]
    return n * block / max(r["wall_time"] for r in rows), statistics.median(r["charts/collect_fps"] for r in rows)
one(False, 1)
one(True, 1)
fps = {False: [], True: []}
for _ in range(3):
    for o in (False, True):
        fps[o].append(one(o, 4))
for k, v in fps.items():
    print("bf16 actor" if k else "fp32 actor", [(round(a), round(c)) for a, c in v], round(statistics.median(a for a, _ in v)))
