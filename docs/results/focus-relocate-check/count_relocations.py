"""Adapted scenes in which some floor object stands in another room than in the scene's base house.

Usage: python count_relocations.py RUNS_A RUNS_B ... (experiment folders with their run scenes,
i.e. before packing: the packed copies here keep no scenes). A child scene is named
``BASE~tNN<tag>KK``; its base house is ``BASE`` in the same run's ``scenes/``.
"""
import sys
from pathlib import Path

from adaptenv.scene.geometry import SceneGeometry
from adaptenv.scene.house import load_house

for folder in sys.argv[1:]:
    n = moved = 0
    types: dict[str, int] = {}
    for seed in sorted(Path(folder, "ours-dr").glob("seed_*")):
        scenes = seed / "scenes"
        for child in sorted(scenes.glob("*~*.json")):
            base = scenes / (child.name.split("~")[0] + ".json")
            if not base.is_file():
                continue
            g0, g1 = (SceneGeometry.from_house(load_house(p, validate=False)) for p in (base, child))
            room = {f.object_id: g0.room_of_point(*f.center) for f in g0.floor_objects}
            other = [f for f in g1.floor_objects if f.object_id in room and g1.room_of_point(*f.center) != room[f.object_id]]
            n += 1
            moved += bool(other)
            for f in other:
                types[f.object_type] = types.get(f.object_type, 0) + 1
    print(folder, f"{moved} of {n} adapted scenes have an object in another room than in their base house", types)
