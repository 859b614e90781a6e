"""Where one gradient step of the map recipe's DAgger learner goes, against a floor of its arithmetic.

Times forward + backward of each part of the map-reading NavNet on a 4,096-frame minibatch (128 chunks
of 32 steps, bf16 autocast as the recipe trains), counts each part's multiply-adds with torch's
FlopCounterMode, and divides by the rate of a large bf16 matmul on the same threads: the floor the
part would reach at that rate. Random inputs of the real shapes. Usage:

    PYTHONPATH=src python docs/results/learner-costs/layer_costs.py [THREADS]
"""

import sys
import time

import torch
import torch.nn.functional as F
from torch.utils.flop_counter import FlopCounterMode

from adaptenv.agents.network import NavNet, NetConfig, configure_torch, unpack_map
from adaptenv.sim.egomap import CROP, MAP_CHANNELS
from adaptenv.sim.spec import N_RAYS, n_classes

configure_torch(int(sys.argv[1]) if len(sys.argv) > 1 else 1)
torch.manual_seed(0)
net = NavNet(NetConfig(map_channels=MAP_CHANNELS)).train()
L, N = 32, 128
g = torch.Generator().manual_seed(0)
obs = {"map": torch.randint(0, 256, (L, N, CROP, CROP), dtype=torch.uint8, generator=g),
       "depth": torch.rand(L, N, N_RAYS, generator=g),
       "semantic": torch.randint(0, n_classes(), (L, N, N_RAYS), generator=g),
       "target": torch.randint(0, n_classes(), (L, N), generator=g),
       "prev_action": torch.randint(0, 4, (L, N), generator=g),
       "collided": torch.randint(0, 2, (L, N), generator=g)}
first = torch.rand(L, N, generator=g) < 0.01
label = torch.randint(0, 4, (L, N), generator=g)
h0 = torch.zeros(N, net.config.hidden)
sem = obs["semantic"].reshape(-1, N_RAYS)
rays = torch.cat([net.class_embed(sem).detach(), obs["depth"].reshape(-1, N_RAYS, 1),
                  (sem == obs["target"].reshape(-1, 1)).float()[..., None]], -1).requires_grad_(True)
feats = torch.randn(L, N, net.config.feature_dim, generator=g).requires_grad_(True)
parts = {
    "scan convolutions": lambda: net.conv(rays.transpose(1, 2)),
    "map unpack": lambda: unpack_map(obs["map"].reshape(-1, CROP, CROP), MAP_CHANNELS, torch.bfloat16),
    "map encoder (unpack included)": lambda: net.map_encoder(
        unpack_map(obs["map"].reshape(-1, CROP, CROP), MAP_CHANNELS, torch.bfloat16)),
    "GRU, 32 steps": lambda: net.recur(feats, first, h0)[0],
    "whole step (loss)": lambda: F.cross_entropy(net(obs, first, h0)[0].float().flatten(0, 1), label.reshape(-1)),
}


def run(fn) -> None:
    with torch.autocast("cpu", dtype=torch.bfloat16):
        y = fn()
    if y.requires_grad:
        y.float().sum().backward()
    net.zero_grad(set_to_none=True)


def median_ms(fn, repeats: int = 7) -> float:
    run(fn)
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        run(fn)
        times.append(time.perf_counter() - t)
    return sorted(times)[repeats // 2] * 1e3


a, b = torch.randn(4096, 1024).bfloat16(), torch.randn(1024, 1024).bfloat16()
rate = 2 * 4096 * 1024 * 1024 / (median_ms(lambda: a @ b) / 1e3)
print(f"threads {torch.get_num_threads()}; bf16 matmul 4096x1024x1024: {rate / 1e9:.0f} GFLOP/s")
print(f"{'part':32s} {'fwd+bwd ms':>10s} {'GFLOP':>7s} {'floor ms':>9s} {'x floor':>8s}")
for name, fn in parts.items():
    counter = FlopCounterMode(display=False)
    with counter:
        run(fn)
    flops = counter.get_total_flops()
    ms = median_ms(fn)
    floor = flops / rate * 1e3
    print(f"{name:32s} {ms:10.1f} {flops / 1e9:7.2f} {floor:9.1f} {ms / floor if floor else float('nan'):8.1f}")
