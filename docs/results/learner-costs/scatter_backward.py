"""Throwaway measurement kept as the record of docs/BENCHMARKS.md, "Where the map learner's gradient step goes"; see the .txt beside it.

The map encoder's first layer as an embedding bag over the 16 bytes of a 4x4 patch: its forward, and the
scatter-adds its weight gradient would need."""
import time

import torch
import torch.nn.functional as F

torch.set_num_threads(1)
def t(fn, reps=7):
    fn(); ts=[]
    for _ in range(reps):
        t0=time.perf_counter(); fn(); ts.append(time.perf_counter()-t0)
    return round(sorted(ts)[reps//2]*1e3, 1)
M = 4096 * 64
idx = torch.randint(0, 256, (M, 16))
G = torch.randn(M, 16)
Gb = G.bfloat16()
def ia():
    out = torch.zeros(16, 256, 16)
    for p in range(16):
        out[p].index_add_(0, idx[:, p], G)
    return out
print("16 index_add fp32", t(ia))
flat = (idx + torch.arange(16) * 256)
def ebag_fwd():
    T = torch.randn(4096, 16)
    return F.embedding_bag(flat, T, mode="sum")
print("ebag fwd", t(ebag_fwd))
def ia_one():
    out = torch.zeros(4096, 16)
    out.index_add_(0, flat.reshape(-1), G.repeat_interleave(16, 0))
print("one index_add (materialized)", t(ia_one))
# via sorting counts: gT = onehot^T G per position using scatter_add on expanded index
def sa():
    out = torch.zeros(4096, 16)
    out.scatter_add_(0, flat.reshape(-1, 1).expand(-1, 16), G[:, None, :].expand(-1, 16, -1).reshape(-1, 16))
print("scatter_add", t(sa))
