"""Throwaway check kept as the record of docs/BENCHMARKS.md, "Where the map learner's gradient step goes": the GRU of
gru-written-out-backward.patch against nn.GRUCell (float64 values and gradients, gradcheck, a float32 step)."""
import torch
from torch import nn

from adaptenv.agents.network import _GRUSequence, gru_sequence

torch.manual_seed(0)
T, B, F_, H = 7, 5, 6, 4
cell = nn.GRUCell(F_, H).double()
x = torch.randn(T, B, F_, dtype=torch.float64, requires_grad=True)
h0 = torch.randn(B, H, dtype=torch.float64, requires_grad=True)
done = torch.rand(T, B) < 0.3
keep = (~done).double()[..., None]
def old():
    h = h0; outs = []
    for t in range(T):
        h = cell(x[t], h * keep[t]); outs.append(h)
    return torch.stack(outs), h
def new():
    gi = nn.functional.linear(x, cell.weight_ih, cell.bias_ih)
    return gru_sequence(gi, keep, h0, cell.weight_hh, cell.bias_hh)
a, b = old(), new()
print("fwd", (a[0]-b[0]).abs().max().item(), (a[1]-b[1]).abs().max().item())
w = torch.randn(T, B, H, dtype=torch.float64); w2 = torch.randn(B, H, dtype=torch.float64)
ga = torch.autograd.grad((a[0]*w).sum() + (a[1]*w2).sum(), [x, h0, *cell.parameters()])
gb = torch.autograd.grad((b[0]*w).sum() + (b[1]*w2).sum(), [x, h0, *cell.parameters()])
print("grads", [ (p-q).abs().max().item() for p, q in zip(ga, gb, strict=False)])
gi = nn.functional.linear(x, cell.weight_ih, cell.bias_ih).detach().requires_grad_(True)
print("gradcheck", torch.autograd.gradcheck(lambda gi, h0, w, b: _GRUSequence.apply(gi, keep, h0, w, b), (gi, h0, cell.weight_hh, cell.bias_hh)))
# fp32 inference bit-identity
c32 = nn.GRUCell(128, 256); x32 = torch.randn(1, 256, 128); h32 = torch.randn(256, 256); k32 = (torch.rand(1, 256) < 0.9).float()[..., None]
with torch.no_grad():
    ref = c32(x32[0], h32 * k32[0])
    out = gru_sequence(nn.functional.linear(x32, c32.weight_ih, c32.bias_ih), k32, h32, c32.weight_hh, c32.bias_hh)[1]
print("fp32 step equal", torch.equal(ref, out), (ref-out).abs().max().item())
