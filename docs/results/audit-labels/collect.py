"""Collect single moves to label and render them: before/after, the moved object highlighted, no verdict shown.

Usage: PYTHONPATH=src python docs/results/audit-labels/collect.py OUT [--per-source N]

Writes OUT/moves.jsonl (one move a line, ``label`` and ``reason`` empty) and OUT/NNN.png (before left, after right,
cropped to the rooms the object stood and stands in). Sources:

- ``builtin``: the built-in G's applied edits (expert policy, 3 steps) on procedural houses of 5 rooms, with the
  placement model off (the hand-written rules only: what G proposed before the model);
- ``random``: random single moves (``random_single_edits``: placement and validation, no plausibility rules) of the
  real ProcTHOR-10K house of tests/data and of procedural houses.

Each move is applied alone to the house before editing (``apply_edit`` of its achieved displacement and yaw).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from PIL import Image

import adaptenv.adapt.plausibility as plausibility
from adaptenv.adapt.edits import Edit, apply_edit
from adaptenv.adapt.placement_model import PlacementModel
from adaptenv.render.topdown import render_map
from adaptenv.scene.geometry import SceneGeometry
from adaptenv.scene.house import House, load_house
from adaptenv.scene.procedural import GenerationConfig, generate_house

REAL = "tests/data/procthor-10k-train-1.json"


def load_source(source: str) -> House:
    """The house a move's ``house`` field names: ``procedural:SEED:ROOMS`` or a house JSON path."""
    if source.startswith("procedural:"):
        _, seed, rooms = source.split(":")
        return generate_house(int(seed), GenerationConfig(n_rooms=int(rooms)))
    return load_house(source, validate=False)


def moved_house(house: House, move: dict) -> House:
    """The house with one labelled move applied."""
    m = move["move"]
    return apply_edit(house, Edit(object_id=move["object"], achieved_dx=m["dx"], achieved_dz=m["dz"],
                                  yaw_before=m["yaw_before"], yaw_after=m["yaw_after"]))


def _row(source: str, edit: Edit, object_type: str, origin: str) -> dict:
    return {"house": source, "object": edit.object_id, "type": object_type, "origin": origin,
            "move": {"dx": round(edit.achieved_dx, 4), "dz": round(edit.achieved_dz, 4),
                     "yaw_before": round(edit.yaw_before or 0.0, 3), "yaw_after": round(edit.yaw_after or 0.0, 3)},
            "label": None, "reason": None}


def builtin_moves(seeds: range) -> list[dict]:
    from adaptenv.adapt.analysis import analyze_trajectory
    from adaptenv.adapt.generators import GenerationContext
    from adaptenv.adapt.generators.builtin import BuiltinGenerator
    from adaptenv.agents.policy import ExpertPolicy
    from adaptenv.agents.rollout import draw_episode, rollout
    from adaptenv.sim.world import compile_world

    off = PlacementModel({})
    plausibility.default_model = lambda: off  # the hand-written rules only
    rows = []
    for seed in seeds:
        source = f"procedural:{seed}:5"
        house = load_source(source)
        world = compile_world(house, "h")
        ep = draw_episode(world, np.random.default_rng([seed, 1]))
        traj = rollout(world, ep, ExpertPolicy())
        ctx = GenerationContext(episode=ep, trajectory=traj, policy=ExpertPolicy(), render=False)
        res = BuiltinGenerator().generate(house, analyze_trajectory(traj, world), steps=3, context=ctx,
                                          rng=np.random.default_rng(seed))
        types = {o.id: o.assetId for o in house.objects}
        geo = SceneGeometry.from_house(house)
        for e in res.applied:
            if e.object_id in types and (e.achieved_dx or e.achieved_dz or e.yaw_after != e.yaw_before):
                rows.append(_row(source, e, geo.footprint(e.object_id).object_type, "builtin G, hand-written rules"))
    return rows


def random_moves(source: str, n: int, seed: int) -> list[dict]:
    from adaptenv.adapt.validation import EditValidator

    house = load_source(source)
    v = EditValidator(house, plausibility=False, move_targets=True)
    rng = np.random.default_rng(seed)
    movable = [f for f in v.geometry.floor_objects if f.movable]
    rows = []
    for _ in range(n * 20):
        if len(rows) >= n:
            break
        f = movable[int(rng.integers(len(movable)))]
        yaw = float(rng.choice([f.yaw, (f.yaw + 90) % 360, (f.yaw + 180) % 360]))
        p = v.propose(f.object_id, *rng.uniform(-12, 12, 2), None if yaw == f.yaw else yaw)
        if p.valid and p.result.changed:
            e = v.commit(p, source="random")
            rows.append(_row(source, e, f.object_type, "random single move"))
            v = EditValidator(house, plausibility=False, move_targets=True)  # every move alone on the original
    return rows


def render_pair(before: House, after: House, object_id: str, path: Path) -> None:
    """Before (left) and after (right), cropped to the moved object's rooms, the object highlighted."""
    imgs = []
    geo_b, geo_a = SceneGeometry.from_house(before), SceneGeometry.from_house(after)
    fb, fa = geo_b.footprint(object_id), geo_a.footprint(object_id)
    rooms = [r for r in (geo_b.room_of_point(*fb.center), geo_a.room_of_point(*fa.center)) if r]
    xs = [c for r in rooms for c in geo_b.rooms[r].bounds[0::2]]
    zs = [c for r in rooms for c in geo_b.rooms[r].bounds[1::2]]
    for h in (before, after):
        r = render_map(h, size=900, highlight={object_id: "red"}, legend=False)
        t = r.layout.transform
        px, pz = t.to_px(np.array([min(xs) - 0.3, max(xs) + 0.3]), np.array([min(zs) - 0.3, max(zs) + 0.3]))
        box = (int(max(0, min(px))), int(max(0, min(pz))), int(min(r.image.width, max(px))),
               int(min(r.image.height, max(pz))))
        imgs.append(r.image.crop(box))
    w = sum(i.width for i in imgs) + 20
    out = Image.new("RGB", (w, max(i.height for i in imgs)), "white")
    out.paste(imgs[0], (0, 0))
    out.paste(imgs[1], (imgs[0].width + 20, 0))
    out.save(path)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out", type=Path)
    ap.add_argument("--per-source", type=int, default=12)
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    rows = random_moves(REAL, args.per_source * 2, 0) + random_moves("procedural:11:5", args.per_source, 1)
    rows += random_moves("procedural:12:4", args.per_source, 2) + builtin_moves(range(10))
    with (args.out / "moves.jsonl").open("w") as fh:
        for k, row in enumerate(rows):
            row = {"id": f"m{k:03d}", **row}
            fh.write(json.dumps(row) + "\n")
            house = load_source(row["house"])
            render_pair(house, moved_house(house, row), row["object"], args.out / f"{row['id']}.png")
    print(f"{len(rows)} moves in {args.out}")


if __name__ == "__main__":
    main()
