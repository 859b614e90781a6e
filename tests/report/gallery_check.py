"""A real adaptation (without the loop) and a pixel check of "after" renders (run_folders.py writes its run).

The scene: the expert finds its target in a procedural house (pi_t in e_t); the floor object nearest
the middle of its path is moved onto that path (e_{t+1}); the expert runs again from the same start
(pi_t's own episode in e_{t+1}). Drawing the *old* path over the edited house would cross the moved
object by construction, which is what :func:`path_pixels_in` detects.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from PIL import Image, ImageDraw, ImageFilter

from adaptenv.render.topdown import END_FILL, START_FILL, MapLayout
from adaptenv.scene.geometry import SceneGeometry
from adaptenv.scene.house import House, move_object
from adaptenv.scene.procedural import generate_house
from adaptenv.sim.rollout import expert_policy, run_episode
from adaptenv.sim.task import sample_episode
from adaptenv.sim.trajectory import Trajectory
from adaptenv.sim.world import compile_world

SEED = 4
"""House and episode seed; the fixture asserts what it relies on, so another seed fails loudly, not silently."""


@dataclass
class AdaptedScene:
    original: House
    edited: House
    before: Trajectory
    after: Trajectory
    moved: str


def adapted_scene(seed: int = SEED) -> AdaptedScene:
    """pi (the expert) in e_t, the object nearest its mid-path moved onto it, pi again in e_{t+1}."""
    house = generate_house(seed)
    episode = sample_episode(compile_world(house, "e_t"), seed)
    before = run_episode(compile_world(house, "e_t"), episode, expert_policy(), policy_name="expert")
    assert before.metrics.success and len(before.steps) >= 30, "the fixture needs a long successful episode"
    mid = before.steps[len(before.steps) // 2].pose
    floor = {f.object_id for f in SceneGeometry.from_house(house).floor_objects} - set(before.target_ids)
    obj = min((o for o in house.objects if o.id in floor),
              key=lambda o: math.hypot(o.position.x - mid.x, o.position.z - mid.z))
    edited = house.model_copy(deep=True)
    moved = next(o for o in edited.objects if o.id == obj.id)
    move_object(moved, mid.x - moved.position.x, mid.z - moved.position.z)
    after = run_episode(compile_world(edited, "e_t+1"), episode, expert_policy(), policy_name="expert")
    return AdaptedScene(house, edited, before, after, obj.id)


def _is_path_colour(rgb: np.ndarray) -> np.ndarray:
    """Pixels drawn by the path (yellow -> orange), or the start/end markers' fills."""
    r, g, b = (rgb[..., k].astype(int) for k in range(3))
    path = (r >= 230) & (b <= 70) & (g >= 95) & (g <= 235)
    near = [np.abs(rgb.astype(int) - np.array(c)).max(axis=-1) <= 30 for c in (START_FILL, END_FILL)]
    return path | near[0] | near[1]


def path_pixels_in(image: Image.Image, layout: MapLayout, house: House, object_ids: list[str],
                   trajectory: Trajectory, inset: int = 2) -> int:
    """How many path-coloured pixels lie inside the objects' footprints (shrunk by ``inset`` px).

    The target crosses (orange, like the path's end) are masked out.
    """
    t = layout.transform
    mask = Image.new("L", image.size, 0)
    draw = ImageDraw.Draw(mask)
    for fp in SceneGeometry.from_house(house).footprints:
        if fp.object_id in object_ids:
            px, py = t.to_px(fp.corners[:, 0], fp.corners[:, 1])
            draw.polygon(list(zip(px.tolist(), py.tolist(), strict=True)), fill=255)
    mask = mask.filter(ImageFilter.MinFilter(2 * inset + 1))
    arm = max(7.0, 0.28 * t.scale) + 4
    for x, z in trajectory.target_positions:
        cx, cy = t.point(x, z)
        draw = ImageDraw.Draw(mask)
        draw.rectangle([cx - arm, cy - arm, cx + arm, cy + arm], fill=0)
    inside = np.asarray(mask) > 0
    assert inside.sum() > 20, "the moved object must cover some pixels for the check to mean anything"
    return int((_is_path_colour(np.asarray(image.convert("RGB"))) & inside).sum())
