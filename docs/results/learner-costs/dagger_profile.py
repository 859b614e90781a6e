"""Throwaway profile kept as the record of docs/BENCHMARKS.md, "Where the map learner's gradient step goes"; see the .txt beside it."""
import cProfile
import pstats

from adaptenv.agents.config import TrainConfig
from adaptenv.agents.houses import load_house_set
from adaptenv.agents.train import train
from adaptenv.bench.train import MAP_RECIPE

worlds = load_house_set("preset:pretrain-train").worlds
block = 256 * 64
def one(n):
    cfg = TrainConfig(frames=n * block, output="", run_dir="", eval_every=0, final_eval_episodes=1,
                      calibrate_episodes=0, progress=False, tensorboard=False, **MAP_RECIPE)
    return train(cfg, worlds=worlds)
one(1)
pr = cProfile.Profile(); pr.enable(); r = one(4); pr.disable()
print([round(x["wall_time"], 2) for x in r.rows if "losses/loss" in x])
st = pstats.Stats(pr); st.sort_stats("cumulative").print_stats(45)
print("=== callees of collect")
st.print_callees("collect")
