"""Throwaway measurement kept as the record of docs/BENCHMARKS.md, "Where the map learner's gradient step goes":
the map recipe serial against --overlap with learner-process.patch applied (a Learner in a spawned process)."""
import statistics
from adaptenv.agents.config import TrainConfig
from adaptenv.agents.train import train
from adaptenv.agents.houses import load_house_set
from adaptenv.bench.train import MAP_RECIPE

def one(worlds, overlap, n):
    block = 256 * 64
    cfg = TrainConfig(frames=n * block, output="", run_dir="", eval_every=0, final_eval_episodes=1,
                      calibrate_episodes=0, progress=False, tensorboard=False, overlap=overlap, **MAP_RECIPE)
    rows = [r for r in train(cfg, worlds=worlds).rows if "losses/loss" in r]
    return (n * block / rows[-1]["wall_time"], statistics.median(r["charts/train_fps"] for r in rows),
            statistics.median(r["charts/collect_fps"] for r in rows))

if __name__ == "__main__":
    worlds = load_house_set("preset:pretrain-train").worlds
    one(worlds, False, 1)
    one(worlds, True, 1)
    res = {False: [], True: []}
    for _ in range(3):
        for o in (False, True):
            res[o].append(one(worlds, o, 6))
    for o, v in res.items():
        print("learner process" if o else "serial", "end-to-end", [round(a) for a, _, _ in v], "median",
              round(statistics.median(a for a, _, _ in v)), "train_fps", round(statistics.median(b for _, b, _ in v)),
              "collect_fps", round(statistics.median(c for _, _, c in v)), flush=True)
