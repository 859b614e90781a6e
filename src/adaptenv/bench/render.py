"""Speed of the top-down renderer on the real 10-room house (target: under 50 ms at 1024 px).

Registered as ``adaptenv bench render [--json]`` by :mod:`adaptenv.cli.render`.

Imports sit inside the functions: this module is loaded by its ``adaptenv bench`` command, and a
benchmark loads what it measures (torch, numba, ray) only when it runs.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np

REAL_HOUSE = Path(__file__).resolve().parents[3] / "tests" / "data" / "procthor-10k-train-1.json"


def random_walk(house, steps: int = 600, seed: int = 0, name: str = "house"):
    """A deterministic wandering episode (mostly forward, turning at obstacles) for benchmarks and demos.

    Moves are checked against the occupancy raster, so blocked moves become collisions
    (``moved=False``) as in a real rollout.
    """
    from adaptenv.scene.geometry import SceneGeometry
    from adaptenv.scene.occupancy import rasterize
    from adaptenv.sim.spec import AGENT_RADIUS, MOVE_STEP
    from adaptenv.sim.trajectory import Pose, Step, Trajectory

    rng = np.random.default_rng(seed)
    geometry = SceneGeometry.from_house(house)
    occ = rasterize(geometry)
    pose = house.agent_pose()
    if pose is None:
        free = np.argwhere(occ.clearance >= AGENT_RADIUS)
        r, c = free[len(free) // 2]
        xs, zs = occ.cell_center(r, c)
        pose = (float(xs), float(zs), 0.0)
    x, z, yaw = pose
    start = Pose(x=x, z=z, yaw=yaw)
    out = []
    for _ in range(steps):
        if rng.random() < 0.12:
            action = "l" if rng.random() < 0.5 else "r"
            out.append(Step(pose=Pose(x=x, z=z, yaw=yaw), action=action))
            yaw = (yaw + (-30.0 if action == "l" else 30.0)) % 360.0
            continue
        h = math.radians(yaw)
        nx, nz = x + MOVE_STEP * math.sin(h), z + MOVE_STEP * math.cos(h)
        ok = float(occ.clearance_at(nx, nz)) >= AGENT_RADIUS
        out.append(Step(pose=Pose(x=x, z=z, yaw=yaw), action="m", moved=ok))
        if ok:
            x, z = nx, nz
        else:
            yaw = (yaw + float(rng.choice([-90.0, -60.0, 60.0, 90.0, 180.0]))) % 360.0
    targets = [f for f in geometry.floor_objects if f.object_type == "Fridge"] or geometry.floor_objects[:1]
    return Trajectory(house=name, target_type=targets[0].object_type if targets else "Fridge",
                      target_ids=[f.object_id for f in targets], target_positions=[f.center for f in targets],
                      start=start, steps=out, final_pose=Pose(x=x, z=z, yaw=yaw), policy="random-walk", seed=seed)


def _median_cpu(fn, repeats: int) -> float:
    """Median process CPU time (s) of ``fn()``: steadier than wall time on a shared, busy machine."""
    import time

    fn()
    times = []
    for _ in range(repeats):
        t = time.process_time()
        fn()
        times.append(time.process_time() - t)
    return float(np.median(times))


def run(house_path: Path = REAL_HOUSE, size: int = 1024, repeats: int = 15) -> dict[str, float]:
    """Median render times (ms) of a house: plain, with grid, and with grid and a 600-step episode."""
    from adaptenv.bench import median_time
    from adaptenv.errors import ConfigError
    from adaptenv.render.topdown import render_house
    from adaptenv.scene.geometry import SceneGeometry
    from adaptenv.scene.house import load_house

    if not Path(house_path).is_file():
        raise ConfigError(f"{house_path}: no such house file (the default needs a source checkout); "
                          "pass one with --house")
    house = load_house(house_path, validate=False)
    traj = random_walk(house, 600, seed=0, name=Path(house_path).name)
    geometry = SceneGeometry.from_house(house)
    figures = {
        "house: rooms": float(len(house.rooms)),
        "house: objects": float(len(house.objects)),
        "size px": float(size),
        "plain ms": median_time(lambda: render_house(house, size=size), repeats) * 1e3,
        "grid ms": median_time(lambda: render_house(house, size=size, grid=True), repeats) * 1e3,
        "grid + 600-step trajectory ms": median_time(
            lambda: render_house(house, size=size, grid=True, trajectory=traj), repeats) * 1e3,
        "grid + trajectory, geometry reused ms": median_time(
            lambda: render_house(house, size=size, grid=True, trajectory=traj, geometry=geometry), repeats) * 1e3,
        "grid + trajectory, CPU ms": _median_cpu(
            lambda: render_house(house, size=size, grid=True, trajectory=traj), repeats) * 1e3,
        "png encode ms": 0.0,
    }
    image = render_house(house, size=size, grid=True, trajectory=traj)
    figures["png encode ms"] = median_time(lambda: image.save(io.BytesIO(), format="PNG"), 5) * 1e3
    return figures

