"""glibc's malloc told to keep freed memory: fewer page faults, the same training results, and the user's settings win."""

from __future__ import annotations

import json
import os
import platform
import resource
import subprocess
import sys

import pytest

from adaptenv.agents.network import KEEP_MEMORY_ENV, keep_freed_memory

glibc = pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="mallopt's thresholds are glibc's")

FAULTS = """
import json, resource, torch
from adaptenv.agents.network import keep_freed_memory
applied = keep_freed_memory()
def cycle():  # a minibatch's activations: 48 MiB in 8 MiB buffers, allocated and freed together
    xs = [torch.ones(2 << 20) for _ in range(6)]
    del xs
for _ in range(3):
    cycle()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(20):
    cycle()
print(json.dumps({"applied": applied, "faults": resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before}))
"""

PPO = """
import hashlib, json, torch
from adaptenv.agents.config import PPOConfig
from adaptenv.agents.network import NavNet, NetConfig, keep_freed_memory
from adaptenv.agents.ppo import train_ppo
from adaptenv.sim.egomap import MAP_CHANNELS
torch.manual_seed(0)
init = NavNet(NetConfig(hidden=32, feature_dim=32, conv_channels=8, map_channels=MAP_CHANNELS))
cfg = PPOConfig(houses="preset:tiny", frames=2048, init="", output="", run_dir="", num_envs=32, rollout_steps=64,
                chunk_len=16, num_minibatches=2, update_epochs=2, eval_every=0, final_eval_episodes=0,
                calibrate_episodes=0, max_episode_steps=60, progress=False, tensorboard=False, threads=1,
                value_warmup_iters=0, kl_coef=0.03, explore_bonus=0.01)
net = train_ppo(cfg, init_net=init).net
digest = hashlib.sha256(b"".join(v.numpy().tobytes() for v in net.state_dict().values())).hexdigest()
print(json.dumps({"applied": keep_freed_memory(), "digest": digest}))
"""


def run_child(code: str, keep: str) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_") and k != "GLIBC_TUNABLES"}
    env[KEEP_MEMORY_ENV] = keep
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


@glibc
def test_kept_memory_is_reused_without_page_faults():
    default, kept = run_child(FAULTS, "0"), run_child(FAULTS, "1")
    assert not default["applied"] and kept["applied"]
    # a heap trimmed after every cycle faults 20 x 48 MiB back in; glibc's default does so only on some heap
    # histories (in the loop's PPO on every minibatch: 1.4 million faults), so the bound is that count
    trimmed = 20 * (48 << 20) // resource.getpagesize()
    assert kept["faults"] < trimmed / 100 and default["faults"] <= trimmed * 1.1


@glibc
def test_kept_memory_trains_the_same_network():
    default, kept = run_child(PPO, "0"), run_child(PPO, "1")
    assert not default["applied"] and kept["applied"]
    assert default["digest"] == kept["digest"]


def test_the_opt_out_and_the_users_own_malloc_settings_win(monkeypatch):
    for name, value in ((KEEP_MEMORY_ENV, "0"), ("MALLOC_TRIM_THRESHOLD_", "131072"),
                        ("MALLOC_TOP_PAD_", "131072"), ("GLIBC_TUNABLES", "glibc.malloc.trim_threshold=131072")):
        with monkeypatch.context() as m:
            m.setenv(name, value)
            keep_freed_memory.cache_clear()
            assert keep_freed_memory() is False
    keep_freed_memory.cache_clear()
