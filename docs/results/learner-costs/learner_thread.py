"""Throwaway measurement kept as the record of docs/BENCHMARKS.md, "Where the map learner's gradient step goes"; see the .txt beside it."""
import statistics

from adaptenv.agents.config import TrainConfig
from adaptenv.agents.houses import load_house_set
from adaptenv.agents.train import train
from adaptenv.bench.train import MAP_RECIPE

worlds = load_house_set("preset:pretrain-train").worlds
block = 256 * 64
def one(overlap, n):
    cfg = TrainConfig(frames=n * block, output="", run_dir="", eval_every=0, final_eval_episodes=1,
                      calibrate_episodes=0, progress=False, tensorboard=False, overlap=overlap, **MAP_RECIPE)
    result = train(cfg, worlds=worlds)
    return n * block / max(r["wall_time"] for r in result.rows if "losses/loss" in r)
one(False, 1)
one(True, 1)
fps = {False: [], True: []}
for _ in range(3):
    for o in (False, True):
        fps[o].append(one(o, 4))
print({k: [round(x) for x in v] for k, v in fps.items()}, {k: round(statistics.median(v)) for k, v in fps.items()})
