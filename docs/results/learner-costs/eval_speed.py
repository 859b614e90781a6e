"""Throwaway measurement kept as the record of docs/BENCHMARKS.md, "Where the map learner's gradient step goes":
256 episodes of the shipped map-reading policy on one thread, as a stand-in for DAgger's collection."""
import time, sys
from adaptenv.agents.network import configure_torch
configure_torch(1)
from adaptenv.agents.houses import load_house_set
from adaptenv.agents.evaluate import run_episodes, sample_episodes
from adaptenv.agents.registry import resolve_policy
worlds = load_house_set("preset:pretrain-train").worlds
pol = resolve_policy("pretrained-map")
eps = sample_episodes(worlds, 256, seed=1)
run_episodes(worlds, eps[:32], pol, batch=32, max_steps=100)
t = time.perf_counter(); res, _ = run_episodes(worlds, eps, pol, batch=256, max_steps=150)
dt = time.perf_counter() - t
print("eval frames/s", round(sum(r.steps for r in res) / dt), "s", round(dt, 2))
