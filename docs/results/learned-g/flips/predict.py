"""How well the edit that makes the agent fail can be picked without rolling the agent out.

    python predict.py OUT.jsonl [...]

Over the tasks whose episode the agent solved: leave-houses-out (5 folds, houses shuffled with seed 0),
a logistic model (h0) or a one-hidden-layer MLP (h32) over the learned G's features ("base"), the
path-exposure features ("expo") or both, and a few fixed rules, each ranking the candidates that passed
every check. "top1 flip": the share of tasks where the first-ranked candidate makes the agent fail the
episode; "any-of-top3": where one of the first three does; "random": the same for a random pick.
"""
import json
import sys

import numpy as np
import torch

recs = [json.loads(l) for f in sys.argv[1:] for l in open(f)]
recs = [r for r in recs if r["base"][0]]
X0, XE, Y, D3, G, H = [], [], [], [], [], []
for gi, r in enumerate(recs):
    for x in r["rows"]:
        if "succ" not in x: continue
        X0.append(x["feat"]); XE.append(x["expo"]); Y.append(1 - x["succ"][0])
        D3.append(np.mean([r["base"][i] - x["succ"][i] for i in range(3)]))
        G.append(gi); H.append(r["job"].split("/")[0])
X0, XE, Y, D3, G, H = map(np.asarray, (X0, XE, Y, D3, G, H))
print("rows", len(Y), "tasks", len(set(G)), "flip rate", Y.mean().round(3), "tasks with a flip", len({g for g, y in zip(G, Y) if y}))
houses = sorted(set(H)); rng = np.random.default_rng(0); rng.shuffle(houses)
folds = [set(houses[i::5]) for i in range(5)]
def fit(Xt, yt, hidden):
    m, s = Xt.mean(0), Xt.std(0) + 1e-6
    xt = torch.tensor((Xt - m) / s, dtype=torch.float32); yt = torch.tensor(yt, dtype=torch.float32)
    torch.manual_seed(0)
    net = torch.nn.Linear(Xt.shape[1], 1) if not hidden else torch.nn.Sequential(torch.nn.Linear(Xt.shape[1], hidden), torch.nn.ReLU(), torch.nn.Linear(hidden, 1))
    opt = torch.optim.Adam(net.parameters(), lr=1e-2, weight_decay=1e-3)
    for _ in range(300):
        loss = torch.nn.functional.binary_cross_entropy_with_logits(net(xt)[:, 0], yt)
        opt.zero_grad(); loss.backward(); opt.step()
    return lambda Xe: net(torch.tensor((Xe - m) / s, dtype=torch.float32))[:, 0].detach().numpy()
def evaluate(score_fn_by_fold, name):
    top1, top3, rnd, rnd3 = [], [], [], []
    for fi, fset in enumerate(folds):
        te = np.array([h in fset for h in H])
        s = score_fn_by_fold(fi, te)
        tidx = np.flatnonzero(te)
        for g in set(G[te]):
            loc = np.flatnonzero(G[tidx] == g); idx = tidx[loc]
            order = idx[np.argsort(-s[loc], kind="stable")]
            top1.append(Y[order[0]]); top3.append(Y[order[:3]].max())
            rnd.append(Y[idx].mean()); rnd3.append(1 - np.prod([1 - Y[idx].mean()] * 3))
    print(f"{name:28s} top1 flip {np.mean(top1):.3f} (random {np.mean(rnd):.3f})  any-of-top3 {np.mean(top3):.3f} (random ~{np.mean(rnd3):.3f})")
XB = np.concatenate([X0, XE], 1)
for name, X in (("base feats", X0), ("expo only", XE), ("base+expo", XB)):
    for hidden in (0, 32):
        evaluate(lambda fi, te, X=X, h=hidden: fit(X[~te], Y[~te], h)(X[te]), f"{name} h{hidden}")
# heuristics: earliest exposure of old or new position within 2 m
evaluate(lambda fi, te: -np.minimum(XE[te, 3], XE[te, 10]), "heur: earliest within 2m")
evaluate(lambda fi, te: -XE[te, 0] - XE[te, 7], "heur: closest to agent path")
evaluate(lambda fi, te: X0[te, 2], "heur: largest move")
from adaptenv.adapt.generators.edit_features import FEATURE_NAMES as FN

i, j = FN.index("d_route"), FN.index("d_route_new")
evaluate(lambda fi, te: -X0[te, i] - X0[te, j], "heur: d_route+d_route_new")
evaluate(lambda fi, te: -X0[te, i], "heur: d_route")
evaluate(lambda fi, te: -XE[te, 0], "heur: agent dist old")
evaluate(lambda fi, te: -XE[te, 7], "heur: agent dist new")
evaluate(lambda fi, te: -XE[te, 0] - XE[te, 7] + 0.5 * X0[te, FN.index("tall")], "heur: agent dist + tall")
