"""Every candidate edit of the learned G on training houses, with its effect on the agent's own episode.

    python probe.py SPEC FIRST STOP OUT.jsonl TASK0 TASK1    # houses FIRST..STOP-1 of SPEC, tasks TASK0..TASK1-1

Per (house, task): an episode the `pretrained` agent solves (seed [7, house, task]), F's analysis, the 64
candidates the learned G draws (seed [7, house, task, 1]) with their features, and for each that passes
placement, validation and the expert: the objectives after it and the agent's success and SPL on the
episode and two other headings ("succ", "spl"; the first is the episode itself). "expo" is the distance
of the object's centre before and after the move to the agent's recorded path (m, capped at 10), and,
within 1, 2 and 4 m, the first point of the path that close (a fraction of its length) and the share
of its points that close. Resumable: finished tasks are skipped.
"""
import json
import math
import sys
import time

import numpy as np

from adaptenv.adapt.analysis import BuiltinAnalyzer
from adaptenv.adapt.generators._trial import moved_geometry
from adaptenv.adapt.generators.builtin import MIN_MOVE
from adaptenv.adapt.generators.edit_features import Scene, candidate_features, enumerate_candidates
from adaptenv.adapt.objectives import RouteSpec, measure
from adaptenv.adapt.validation import EditValidator
from adaptenv.agents.houses import load_house_set
from adaptenv.agents.registry import resolve_policy
from adaptenv.agents.rollout import checking_episodes, find_solved_episode, run_in_worlds
from adaptenv.sim.rollout import expert_policy, run_episode
from adaptenv.sim.world import compile_world

spec, start, stop, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
T0, T1 = int(sys.argv[5]), int(sys.argv[6])
hs = load_house_set(spec)
agent = resolve_policy("pretrained", seed=0)
expert = expert_policy()
done = set()
try:
    for line in open(out):
        done.add(json.loads(line)["job"])
except FileNotFoundError:
    pass
for n in range(start, min(stop, len(hs.houses))):
    house, name = hs.houses[n], hs.worlds[n].name
    for task in range(T0, T1):
        job = f"{name}/{task}"
        if job in done:
            continue
        t0 = time.perf_counter()
        world = compile_world(house, name)
        found = find_solved_episode(world, agent, np.random.default_rng([7, n, task]), tries=10)
        if found is None:
            continue
        ep, before = found
        analysis = BuiltinAnalyzer().analyze(before, world)
        v = EditValidator(house, episode_targets=[ep.target_type], start=ep.start[:2])
        route = RouteSpec.from_episode(ep.target_type, ep.start, before)
        scene = Scene.of(v, world, route)
        rng = np.random.default_rng([7, n, task, 1])
        cands = enumerate_candidates(v, world, route, rng, 64, scene=scene)
        feats = candidate_features(v, scene, cands, analysis)
        obj0 = measure(world, route).as_dict()
        ap = route.agent_points if len(route.agent_points) else scene.start[None, :]
        upm = v.ctx.grid.units_per_meter
        def expo(p):
            d = np.hypot(ap[:, 0] - p[0], ap[:, 1] - p[1])
            out = [float(min(d.min(), 10.0))]
            for R in (1.0, 2.0, 4.0):
                hit = np.flatnonzero(d <= R)
                out += [float(hit[0]) / len(d) if len(hit) else 1.0, float(len(hit)) / len(d)]
            return out
        rows, worlds, idx = [], [], []
        for k, c in enumerate(cands):
            p = v.propose(c.object_id, c.dx_units, c.dy_units, c.rotation, relocate=c.relocate)
            res = p.result
            ok = p.valid and res.changed and (res.rotation_applied or math.hypot(*res.achieved) >= MIN_MOVE)
            row = {"k": k, "kind": c.kind, "obj": c.object_id, "valid": bool(p.valid), "ok": bool(ok),
                   "ach": [float(res.achieved[0]), float(res.achieved[1])], "feat": [float(x) for x in feats[k]],
                   "expo": expo(v.ctx.centers[v.ctx.index[c.object_id]]) + expo(v.ctx.centers[v.ctx.index[c.object_id]] + np.array([c.dx_units, c.dy_units]) / upm)}
            if ok:
                cw = compile_world(v.house, "candidate", geometry=moved_geometry(v.geometry, res))
                if run_episode(cw, ep, expert, record=False).metrics.success:
                    row["obj_after"] = measure(cw, route).as_dict()
                    worlds.append(cw); idx.append(k)
            rows.append(row)
        eps = checking_episodes(ep, 3)
        runs = run_in_worlds([world, *worlds], eps, agent)
        base = [bool(t.metrics.success) for t in runs[0]]
        for k, trajs in zip(idx, runs[1:]):
            rows[k]["succ"] = [bool(t.metrics.success) for t in trajs]
            rows[k]["spl"] = [float(t.metrics.spl) for t in trajs]
        rec = {"job": job, "n": n, "task": task, "target": ep.target_type, "base": base, "obj0": obj0,
               "analysis_success": analysis.outcome.success, "rows": rows,
               "seconds": round(time.perf_counter() - t0, 2)}
        with open(out, "a") as f:
            f.write(json.dumps(rec) + "\n")
        print(job, len(cands), len(worlds), rec["seconds"], flush=True)
