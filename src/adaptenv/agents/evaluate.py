"""Evaluation harness: run a policy on many episodes in batch and report ObjectNav metrics.

Episodes are drawn deterministically from a seed (episode k gets its own generator seeded by
``(seed, k)`` and house ``k mod n_houses``), run B at a time through :class:`BatchSim` (a finished
slot immediately takes the next episode), and scored with SPOC's metrics: success, SPL, SEL
(success weighted by the expert's episode length over the agent's), collisions and episode length,
each as mean +- standard error, with a Wilson interval for success and a normal interval for SPL.
Trajectories are recorded for failed episodes and drawn as a grid of top-down maps.

Built-in policies are deterministic per episode (networks and random actions draw from
generators re-seeded by each episode's seed; the expert has no randomness), so results do not
depend on the batch size or the number of workers.

Example::

    adaptenv evaluate --policy pretrained --houses preset:pretrain-train --episodes 200 -o runs/eval
"""

from __future__ import annotations

import csv
import json
import math
import multiprocessing as mp
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image, ImageDraw

from adaptenv.agents.houses import HouseSet, compile_houses
from adaptenv.agents.policy import ExpertPolicy, Policy, policy_name
from adaptenv.agents.registry import resolve_policy, weights_record
from adaptenv.agents.runner import EpisodeResult, Recorded, run_episodes
from adaptenv.agents.suites import EpisodeFloor, sample_floored
from adaptenv.files import atomic_path, atomic_write_text
from adaptenv.sim import task
from adaptenv.sim.spec import ACTIONS, MAX_STEPS
from adaptenv.sim.trajectory import Pose, Step, Trajectory
from adaptenv.sim.world import NavWorld

Z95 = 1.959963984540054


def sample_episodes(worlds: Sequence[NavWorld], n: int, seed: int, *, use_house_start: bool = False, start: int = 0,
                    floor: EpisodeFloor | None = None) -> list[tuple[int, task.Episode]]:
    """Episodes ``start..n-1`` as (house index, Episode) pairs: house ``k % len(worlds)``, episode seed
    derived from ``(seed, k)``, so any slice equals the same slice of the whole list.

    ``floor`` (default: the floor a ``suite:`` house set carries, see :mod:`adaptenv.agents.suites`)
    keeps only starts far enough from the target.
    """
    floor = floor if floor is not None else getattr(worlds, "floor", None)
    if floor is not None and floor.active and not use_house_start:
        return sample_floored(worlds, n, seed, floor, start=start)
    out = []
    for k in range(start, n):
        e = k % len(worlds)
        ep_seed = int(np.random.SeedSequence([seed, k]).generate_state(1)[0])
        ep = task.sample_episode(worlds[e], ep_seed, use_house_start=use_house_start)
        out.append((e, ep))
    return out


def add_sel(results: list[EpisodeResult], expert: list[EpisodeResult]) -> None:
    """Fill SEL = success * expert_steps / max(steps, expert_steps) from the expert's runs (in place)."""
    for r, x in zip(results, expert, strict=True):
        r.expert_steps = x.steps if x.success else None
        if r.success and x.success:
            r.sel = x.steps / max(r.steps, x.steps)
        else:
            r.sel = 0.0 if not r.success else float("nan")


# -- statistics ------------------------------------------------------------------------------------

def mean_se(values: Sequence[float]) -> tuple[float, float]:
    """Mean and standard error of the finite values (NaNs dropped)."""
    v = np.asarray([x for x in values if x is not None and math.isfinite(x)], dtype=np.float64)
    if v.size == 0:
        return float("nan"), float("nan")
    se = float(v.std(ddof=1) / math.sqrt(v.size)) if v.size > 1 else float("nan")
    return float(v.mean()), se


def wilson(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a proportion (95% by default)."""
    if n == 0:
        return float("nan"), float("nan")
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


def summarize(results: Sequence[EpisodeResult]) -> dict[str, Any]:
    """Mean +- standard error of every metric, Wilson CI of success, normal CI of SPL."""
    n = len(results)
    wins = sum(r.success for r in results)
    out: dict[str, Any] = {"episodes": n, "successes": wins}
    for key in ("success", "spl", "sel", "collisions", "steps", "path_length"):
        m, se = mean_se([float(getattr(r, key)) for r in results])
        out[key] = m
        out[f"{key}_se"] = se
    out["success_ci95"] = list(wilson(wins, n))
    out["spl_ci95"] = [out["spl"] - Z95 * out["spl_se"], out["spl"] + Z95 * out["spl_se"]]
    return out


def per_house(results: Sequence[EpisodeResult]) -> list[dict[str, Any]]:
    """One row per house: episodes, success, SPL, SEL, collisions, steps (means)."""
    rows = []
    for house in sorted({r.house for r in results}):
        rs = [r for r in results if r.house == house]
        s = summarize(rs)
        rows.append({"house": house, "episodes": len(rs), **{k: s[k] for k in
                                                              ("success", "spl", "sel", "collisions", "steps")}})
    return rows


def by_rooms(results: Sequence[EpisodeResult], rooms: Sequence[int]) -> list[dict[str, Any]]:
    """Success and SPL by the number of rooms of the episode's house (``rooms[env]``), fewest rooms first: one row
    per room count with its houses, episodes, success (Wilson 95% interval) and SPL."""
    rows = []
    for n in sorted({rooms[r.env] for r in results}):
        rs = [r for r in results if rooms[r.env] == n]
        s = summarize(rs)
        rows.append({"rooms": n, "houses": len({r.env for r in rs}), "episodes": len(rs), "success": s["success"],
                     "success_ci_low": s["success_ci95"][0], "success_ci_high": s["success_ci95"][1],
                     "spl": s["spl"]})
    return rows


def by_rooms_line(rows: Sequence[dict[str, Any]]) -> str:
    """The by-rooms breakdown in one line: ``success by rooms: 2: 0.97 (30 ep), 8: 0.75 (40 ep)``."""
    return "success by rooms: " + ", ".join(f"{r['rooms']}: {r['success']:.2f} ({r['episodes']} ep)" for r in rows)


def paired_difference(results: Sequence[EpisodeResult], base: Sequence[EpisodeResult],
                      key: str = "success") -> dict[str, Any]:
    """Mean per-episode difference results - base of a metric over the same episodes, with a 95% normal interval."""
    diffs = [float(getattr(r, key)) - float(getattr(b, key)) for r, b in zip(results, base, strict=True)]
    d, se = mean_se(diffs)
    return {"diff": d, "se": se, "ci95": [d - Z95 * se, d + Z95 * se]}


def drop(base: dict[str, Any], other: dict[str, Any], key: str = "success") -> dict[str, float]:
    """Difference base - other of a metric with a 95% normal interval (independent samples)."""
    d = base[key] - other[key]
    se = math.sqrt(base[f"{key}_se"] ** 2 + other[f"{key}_se"] ** 2)
    return {"drop": d, "se": se, "ci95": [d - Z95 * se, d + Z95 * se]}


# -- the harness -----------------------------------------------------------------------------------

@dataclass
class EvalReport:
    """Everything one evaluation produced (also written to the output folder)."""

    policy: str
    houses: str
    seed: int
    summary: dict[str, Any]
    results: list[EpisodeResult]
    recordings: dict[int, Recorded]


def _build_policy(policy: Policy | str, seed: int, wrap: Callable[[Policy], Policy] | None) -> Policy:
    """The policy a run drives: ``policy`` (resolved with ``seed`` when a spec), wrapped by ``wrap`` if given."""
    pol = resolve_policy(policy, seed=seed) if isinstance(policy, str) else policy
    return wrap(pol) if wrap is not None else pol


def _evaluate_shard(args: tuple) -> tuple[list[EpisodeResult], dict[int, Recorded], list[EpisodeResult]]:
    """Worker entry: evaluate a slice of the episodes (and the expert on it) in a fresh process."""
    policy_spec, houses, names, episodes, batch, max_steps, with_expert, seed, wrap = args
    # torch: loaded in worker processes only
    from adaptenv.agents.network import configure_torch
    configure_torch(1)
    worlds = compile_houses(houses, names)
    policy = _build_policy(policy_spec, seed, wrap)
    results, recs = run_episodes(worlds, episodes, policy, batch=batch, max_steps=max_steps,
                                 record=lambda r: not r.success)
    expert: list[EpisodeResult] = []
    if with_expert:
        expert, _ = run_episodes(worlds, episodes, ExpertPolicy(), batch=batch, max_steps=max_steps)
    return results, recs, expert


def evaluate(policy: Policy | str, house_set: HouseSet, *, episodes: int = 200, seed: int = 0, batch: int = 64,
             workers: int = 1, max_steps: int = MAX_STEPS, with_expert: bool = True,
             progress: Callable[[int], None] | None = None, floor: EpisodeFloor | None = None,
             wrap: Callable[[Policy], Policy] | None = None) -> EvalReport:
    """Evaluate ``policy`` (an object, or a ``--policy`` spec when using workers) on a HouseSet.

    With ``workers > 1`` the episodes are split in contiguous slices over a process pool (spawned,
    one torch thread each); the policy must then be given as a spec string (resolved with ``seed``
    in every process). ``floor`` overrides the start-distance floor of a ``suite:`` house set (see
    :func:`sample_episodes`). ``wrap`` (picklable for workers, e.g. ``functools.partial(WipeMemory,
    every=8)``) wraps the policy in every process.
    """
    worlds = house_set.worlds
    eps = sample_episodes(worlds, episodes, seed, floor=floor)
    name = policy if isinstance(policy, str) else policy_name(policy)
    if workers > 1:
        if not isinstance(policy, str):
            raise TypeError("evaluate(workers > 1) needs the policy as a --policy spec string")
        bounds = np.linspace(0, len(eps), workers + 1).astype(int)
        shards = [(policy, house_set.houses, house_set.names, eps[a:b], batch, max_steps, with_expert, seed, wrap)
                  for a, b in zip(bounds[:-1], bounds[1:], strict=True) if b > a]
        results, recordings, expert = [], {}, []
        with ProcessPoolExecutor(len(shards), mp_context=mp.get_context("spawn")) as pool:
            offset = 0
            for shard, (res, recs, exp) in zip(shards, pool.map(_evaluate_shard, shards), strict=True):
                for r in res + exp:
                    r.index += offset
                results += res
                expert += exp
                recordings.update({k + offset: v for k, v in recs.items()})
                offset += len(shard[3])
                if progress is not None:
                    progress(len(results))
    else:
        results, recordings = run_episodes(worlds, eps, _build_policy(policy, seed, wrap), batch=batch, max_steps=max_steps,
                                           record=lambda r: not r.success, progress=progress)
        expert = run_episodes(worlds, eps, ExpertPolicy(), batch=batch, max_steps=max_steps)[0] if with_expert else []
    if with_expert:
        add_sel(results, expert)
    summary = summarize(results)
    active = floor if floor is not None else getattr(worlds, "floor", None)
    if active is not None and active.active:
        summary["floor"] = active.label()
        summary["floor_left_out"] = [house_set.names[e] for e in floor_left_out(eps, len(worlds))]
        summary["houses_used"], summary["houses_in_set"] = len({e for e, _ in eps}), len(worlds)
    if with_expert:
        summary["expert_success"] = summarize(expert)["success"]
    summary["skipped_houses"] = {h.name: h.reason for h in getattr(house_set, "skipped", [])}
    summary["by_rooms"] = by_rooms(results, room_counts(house_set))
    return EvalReport(name, house_set.spec, seed, summary, results, recordings)


def room_counts(house_set: HouseSet) -> list[int]:
    """The number of rooms of each house of a set, in its worlds' order."""
    return [len(h.rooms) for h in house_set.houses]


def floor_left_out(eps: Sequence[tuple[int, task.Episode]], n_houses: int) -> list[int]:
    """Houses an episode floor left out: episode k belongs to house ``k % n_houses`` and goes to a later
    house only when that one has no start far enough from a target (sorted house indices)."""
    return sorted({k % n_houses for k, (e, _) in enumerate(eps) if e != k % n_houses})


def trajectory_of(world: NavWorld, result: EpisodeResult, rec: Recorded, policy: str) -> Trajectory:
    """Build a :class:`~adaptenv.sim.trajectory.Trajectory` from a recording (for rendering)."""
    targets = world.instances_of(result.target_type)
    steps = [Step(pose=Pose(x=p[0], z=p[1], yaw=p[2]), action=ACTIONS[a], moved=m)
             for p, a, m in zip(rec.poses[:-1], rec.actions, rec.moved, strict=True)]
    last = rec.poses[-1]
    return Trajectory(house=str(world.name), target_type=result.target_type,
                      target_ids=[t.object_id for t in targets],
                      target_positions=[tuple(map(float, t.center)) for t in targets],
                      start=Pose(x=rec.start[0], z=rec.start[1], yaw=rec.start[2]), steps=steps,
                      final_pose=Pose(x=last[0], z=last[1], yaw=last[2]), policy=policy, seed=result.seed)


def failure_grid(report: EvalReport, house_set: HouseSet, *, render: Callable[..., Image.Image], limit: int = 12,
                 tile: int = 360, columns: int = 4) -> Image.Image | None:
    """A PIL image tiling top-down renders of the first ``limit`` failed episodes (None if none failed).

    ``render(house, trajectory=...)`` draws one episode, e.g. :func:`adaptenv.render.topdown.render_house`
    (passed in: rendering is a layer above the agents).
    """
    failed = [r for r in report.results if not r.success and r.index in report.recordings][:limit]
    if not failed:
        return None
    rows = math.ceil(len(failed) / columns)
    caption = 22
    grid = Image.new("RGB", (columns * tile, rows * (tile + caption)), "white")
    draw = ImageDraw.Draw(grid)
    for j, r in enumerate(failed):
        traj = trajectory_of(house_set.worlds[r.env], r, report.recordings[r.index], report.policy)
        img = render(house_set.houses[r.env], trajectory=traj).convert("RGB")
        img.thumbnail((tile, tile))
        x, y = (j % columns) * tile, (j // columns) * (tile + caption)
        grid.paste(img, (x + (tile - img.width) // 2, y + caption))
        draw.text((x + 4, y + 4), f"#{r.index} {r.house} -> {r.target_type} ({r.steps} steps)", fill="black")
    return grid


def write_report(report: EvalReport, house_set: HouseSet, out: Path, *, command: str = "",
                 render: Callable[..., Image.Image] | None = None) -> dict[str, Path]:
    """Write summary.json, episodes.csv, houses.csv, rooms.csv (success by the number of rooms), failed trajectories and, given ``render`` (see
    :func:`failure_grid`; the CLI and the loop pass ``render_house``), failures.png to ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    paths = {"summary": out / "summary.json", "episodes": out / "episodes.csv", "houses": out / "houses.csv",
             "rooms": out / "rooms.csv"}
    rooms = report.summary.get("by_rooms") or by_rooms(report.results, room_counts(house_set))
    doc = {"policy": report.policy, "weights": weights_record(report.policy), "houses": report.houses,
           "seed": report.seed, "command": command, **report.summary, "by_rooms": rooms}
    atomic_write_text(paths["summary"], json.dumps(doc, indent=1, default=float) + "\n")
    rows = [asdict(r) for r in report.results]
    _write_csv(paths["episodes"], rows)
    _write_csv(paths["houses"], per_house(report.results))
    _write_csv(paths["rooms"], rooms)
    grid = failure_grid(report, house_set, render=render) if render is not None else None
    if grid is not None:
        paths["failures"] = out / "failures.png"
        with atomic_path(paths["failures"]) as tmp:
            grid.save(tmp)
    tdir = out / "failed"
    for r in report.results:
        if not r.success and r.index in report.recordings:
            trajectory_of(house_set.worlds[r.env], r, report.recordings[r.index],
                          report.policy).save(tdir / f"episode_{r.index:04d}.json")
    return paths


def _write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    if not rows:
        atomic_write_text(path, "")
        return
    with atomic_path(path) as tmp, tmp.open("w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
