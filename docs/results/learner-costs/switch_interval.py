"""Throwaway measurement kept as the record of docs/BENCHMARKS.md, "Where the map learner's gradient step goes":
the learner thread under three interpreter switch intervals (the first run warms the caches)."""
import sys
from adaptenv.agents.config import TrainConfig
from adaptenv.agents.train import train
from adaptenv.agents.houses import load_house_set
from adaptenv.bench.train import MAP_RECIPE
worlds = load_house_set("preset:pretrain-train").worlds
block = 256 * 64
for overlap, si in ((True, 0.005), (True, 0.0005), (True, 0.0001), (False, 0.005), (True, 0.005), (True, 0.0005)):
    sys.setswitchinterval(si)
    cfg = TrainConfig(frames=5 * block, output="", run_dir="", eval_every=0, final_eval_episodes=1,
                      calibrate_episodes=0, progress=False, tensorboard=False, overlap=overlap, **MAP_RECIPE)
    rows = [r for r in train(cfg, worlds=worlds).rows if "losses/loss" in r]
    print("overlap" if overlap else "serial", "switch", si, "end-to-end", round(5 * block / rows[-1]["wall_time"]),
          "train_fps", [round(r["charts/train_fps"]) for r in rows], "collect_fps", [round(r["charts/collect_fps"]) for r in rows], flush=True)
