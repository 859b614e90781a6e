"""Throwaway measurement kept as the record of docs/BENCHMARKS.md, "Where the map learner's gradient step goes":
the map recipe end to end with a smaller network, side by side with the shipped size (fresh weights)."""
import statistics
from adaptenv.agents.config import TrainConfig
from adaptenv.agents.train import train
from adaptenv.agents.houses import load_house_set
from adaptenv.bench.train import MAP_RECIPE
worlds = load_house_set("preset:pretrain-train").worlds
block = 256 * 64
sizes = {"default": {}, "gru128": {"hidden": 128}, "gru128-conv16": {"hidden": 128, "conv_channels": 16}}
def one(kw, n):
    cfg = TrainConfig(frames=n * block, output="", run_dir="", eval_every=0, final_eval_episodes=1,
                      calibrate_episodes=0, progress=False, tensorboard=False, **MAP_RECIPE, **kw)
    rows = [r for r in train(cfg, worlds=worlds).rows if "losses/loss" in r]
    return n * block / rows[-1]["wall_time"], statistics.median(r["charts/train_fps"] for r in rows), statistics.median(r["charts/collect_fps"] for r in rows)
for kw in sizes.values():
    one(kw, 1)
res = {k: [] for k in sizes}
for _ in range(3):
    for k, kw in sizes.items():
        res[k].append(one(kw, 4))
for k, v in res.items():
    print(k, "end-to-end", [round(a) for a, _, _ in v], "median", round(statistics.median(a for a, _, _ in v)),
          "train_fps", round(statistics.median(b for _, b, _ in v)), "collect_fps", round(statistics.median(c for _, _, c in v)))
