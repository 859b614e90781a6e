"""Throwaway measurement kept as the record of docs/BENCHMARKS.md, "Where the map learner's gradient step goes"; see the .txt beside it."""
import sys
import time

import torch
import torch.nn.functional as F

from adaptenv.agents.network import NavNet, NetConfig, configure_torch, unpack_map
from adaptenv.sim.egomap import CROP, MAP_CHANNELS
from adaptenv.sim.spec import N_RAYS

configure_torch(int(sys.argv[1]))
torch.manual_seed(0)
net = NavNet(NetConfig(map_channels=MAP_CHANNELS))
N = 4096
g = torch.Generator().manual_seed(0)
packed = torch.randint(0, 256, (N, CROP, CROP), dtype=torch.uint8, generator=g)
rays = torch.randn(N, N_RAYS, 18, generator=g)
def t(fn, reps=7):
    fn(); ts=[]
    for _ in range(reps):
        t0=time.perf_counter(); fn(); ts.append(time.perf_counter()-t0)
    return sorted(ts)[reps//2]*1e3
c1, c2 = net.conv[0], net.conv[2]
m1, m2, lin = net.map_encoder[0], net.map_encoder[2], net.map_encoder[5]
def scan_now(r):
    return net.conv(r.transpose(1, 2)).flatten(1)
def conv1d_cl(x, conv):
    """x (N, L, C) channels-last; conv1d as im2col + linear; output (N, Lout, O)."""
    k, s, p = conv.kernel_size[0], conv.stride[0], conv.padding[0]
    x = F.pad(x, (0, 0, p, p))
    cols = x.unfold(1, k, s)  # (N, Lout, C, k)
    return F.linear(cols.reshape(*cols.shape[:2], -1), conv.weight.reshape(conv.weight.shape[0], -1), conv.bias)
def scan_new(r):
    y = torch.relu(conv1d_cl(r, c1))
    y = torch.relu(conv1d_cl(y, c2))
    return y.transpose(1, 2).flatten(1)
def map_now(pk):
    dt = torch.bfloat16 if torch.is_autocast_enabled("cpu") else torch.float32
    return net.map_encoder(unpack_map(pk, 8, dt))
TABLE = ((torch.arange(256)[:, None] >> torch.arange(8)) & 1)
def map_new(pk):
    dt = torch.bfloat16 if torch.is_autocast_enabled("cpu") else torch.float32
    n = pk.shape[0]
    patches = pk.view(n, 8, 4, 8, 4).transpose(2, 3)  # (n, py, px, dy, dx)
    x = F.embedding(patches.reshape(n, 8, 8, 16).int(), TABLE.to(dt)).reshape(n, 8, 8, 128)  # (dy, dx, c)
    y = torch.relu(F.linear(x, m1.weight.permute(0, 2, 3, 1).reshape(16, 128), m1.bias))  # (n, 8, 8, 16)
    y = F.pad(y, (0, 0, 1, 0, 1, 0))  # (n, 9, 9, 16): stride 2, pad 1, k3 -> rows -1..7 needed: pad top/left 1
    cols = y.unfold(1, 3, 2).unfold(2, 3, 2)  # (n, 4, 4, 16, 3, 3)
    y = torch.relu(F.linear(cols.reshape(n, 4, 4, 144), m2.weight.reshape(32, 144), m2.bias))
    y = y.permute(0, 3, 1, 2).flatten(1)
    return torch.relu(lin(y))
with torch.autocast("cpu", dtype=torch.bfloat16):
    a, b = scan_now(rays).float(), scan_new(rays).float()
    print("scan diff", (a - b).abs().max().item(), a.abs().max().item())
    a, b = map_now(packed).float(), map_new(packed).float()
    print("map diff", (a - b).abs().max().item(), a.abs().max().item())
with torch.no_grad():
    a, b = scan_now(rays), scan_new(rays)
    print("fp32 scan diff", (a - b).abs().max().item())
    a, b = map_now(packed), map_new(packed)
    print("fp32 map diff", (a - b).abs().max().item())
rg = rays.clone().requires_grad_(True)
def fb(fn, x):
    def go():
        with torch.autocast("cpu", dtype=torch.bfloat16):
            y = fn(x)
        y.float().sum().backward()
    return go
for name, fn, x in [("scan now", scan_now, rg), ("scan new", scan_new, rg), ("map now", map_now, packed), ("map new", map_new, packed)]:
    print(name, round(t(fb(fn, x)), 1), "ms")
