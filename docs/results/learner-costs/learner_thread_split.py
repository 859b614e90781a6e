"""Throwaway measurement kept as the record of docs/BENCHMARKS.md, "Where the map learner's gradient step goes":
the learner's and the collection's own rates, serial on two threads, with the learner thread, serial on one."""
import statistics
from adaptenv.agents.config import TrainConfig
from adaptenv.agents.train import train
from adaptenv.agents.houses import load_house_set
from adaptenv.bench.train import MAP_RECIPE
worlds = load_house_set("preset:pretrain-train").worlds
block = 256 * 64
for overlap, threads in ((False, 0), (True, 0), (False, 1)):
    cfg = TrainConfig(frames=5 * block, output="", run_dir="", eval_every=0, final_eval_episodes=1, threads=threads,
                      calibrate_episodes=0, progress=False, tensorboard=False, overlap=overlap, **MAP_RECIPE)
    rows = [r for r in train(cfg, worlds=worlds).rows if "losses/loss" in r]
    print("overlap" if overlap else "serial", "threads", threads, "end-to-end", round(5 * block / rows[-1]["wall_time"]),
          "train_fps", [round(r["charts/train_fps"]) for r in rows], "collect_fps", [round(r["charts/collect_fps"]) for r in rows])
