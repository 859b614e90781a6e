"""Throwaway measurement kept as the record of docs/BENCHMARKS.md, "Where the map learner's gradient step goes":
the map recipe's gradient step on one thread, repeated for DUR seconds (random inputs of the real shapes)."""
import os
import sys, time, torch, numpy as np
import torch.nn.functional as F
from adaptenv.agents.network import NavNet, NetConfig, configure_torch
from adaptenv.agents.train import sequence_logits
from adaptenv.sim.egomap import MAP_CHANNELS, CROP
from adaptenv.sim.spec import N_RAYS, n_classes
configure_torch(1)
torch.manual_seed(0)
net = NavNet(NetConfig(map_channels=MAP_CHANNELS)); net.train()
opt = torch.optim.Adam(net.parameters(), 1e-3)
L, N = 32, 128
g = torch.Generator().manual_seed(0)
def batch():
    return {"map": torch.randint(0, 256, (L, N, CROP, CROP), dtype=torch.uint8, generator=g),
            "depth": torch.rand(L, N, N_RAYS, generator=g),
            "semantic": torch.randint(0, n_classes(), (L, N, N_RAYS), generator=g),
            "target": torch.randint(0, n_classes(), (L, N), generator=g),
            "prev_action": torch.randint(0, 4, (L, N), generator=g),
            "collided": torch.randint(0, 2, (L, N), generator=g),
            "first": torch.rand(L, N, generator=g) < 0.01,
            "label": torch.randint(0, 4, (L, N), generator=g),
            "h0": torch.zeros(N, 256)}
def step(b):
    logits = sequence_logits(net, b, b["first"], b["h0"], "bf16")
    loss = F.cross_entropy(logits.reshape(-1, logits.shape[-1]), b["label"].reshape(-1))
    opt.zero_grad(); loss.backward(); torch.nn.utils.clip_grad_norm_(net.parameters(), 1.0); opt.step()
bs = [batch() for _ in range(4)]
for b in bs:
    step(b)
t0, n = time.perf_counter(), 0
while time.perf_counter() - t0 < float(os.environ.get("DUR", "20")):
    step(bs[n % 4])
    n += 1
print("grad step ms", round((time.perf_counter() - t0) / n * 1e3, 1), n)
