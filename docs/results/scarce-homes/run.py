"""The scarce-homes lever test of DECLARED.md, resumable: every finished (mode, arm, N, seed) is skipped.

Usage, from a clone with the virtual environment of `make install-dev`:

    .venv/bin/python docs/results/scarce-homes/run.py OUT [--jobs K] [--only MODE-ARM-N-SEED ...]

``--jobs K`` runs the first K unfinished jobs of the declared order and stops (the order is the
declaration's: the primary arms first). Each job trains a fresh network by DAgger from the map
explorer (``adaptenv train``'s library call) on its arm's houses for the declared budget, keeping
snapshots at each quarter, then evaluates the snapshots on the validation suites and the final policy
on the held-out suites and the tail, and writes ``OUT/results/<job>.json``. A job interrupted in
training resumes from its ``state.pt``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict
from pathlib import Path

from adaptenv.agents.checkpoint import load_checkpoint
from adaptenv.agents.evaluate import evaluate
from adaptenv.agents.houses import load_house_set
from adaptenv.agents.tail import tail_success
from adaptenv.agents.train import TrainConfig, snapshot_path, train
from adaptenv.scene.house import save_house
from adaptenv.scene.procedural import generate_preset

BUDGET = 6_094_848
"""B: frames of every arm (372 iterations of 256 x 64; DECLARED.md, amendment 2: twice amendment 1's B)."""
SNAPSHOTS = 4
HELDOUT = {"far": "suite:far", "long-unseen": "suite:long-unseen", "rearranged": "suite:rearranged",
           "unseen-assets": "suite:unseen-assets"}
VALIDATION = {"val-long": "suite:val-long", "val-unseen-assets": "suite:val-unseen-assets"}
HELDOUT_EPISODES, VALIDATION_EPISODES = 300, 100
#: Training houses of each arm for N seed homes: preset names (several are joined).
ARMS = {
    24: {"none": ["pretrain-train"], "fresh": ["fresh-240"], "swap": ["pretrain-swapped"],
         "rearrange": ["pretrain-rearranged10"], "oracle": ["oracle-large", "oracle-unseen", "oracle-test-assets"]},
    6: {"none": ["scarce-6"], "fresh": ["fresh-60"], "swap": ["scarce-6-swapped"],
        "rearrange": ["scarce-6-rearranged"], "oracle": ["oracle-large", "oracle-unseen", "oracle-test-assets"]},
}
ORACLE_SHARE = {24: 80, 6: 20}
"""Houses taken from each oracle preset: 10 N in all."""


def declared_jobs() -> list[tuple[str, str, int, int]]:
    """(perception, arm, N, seed) in the declared order: N = 24 seed by seed, then N = 6, then the labelled control."""
    arms = ("none", "fresh", "swap", "rearrange", "oracle")
    jobs = [("shape", a, 24, s) for s in range(5) for a in arms]
    jobs += [("shape", a, 6, s) for s in range(3) for a in arms]
    jobs += [("labels", a, 24, s) for s in range(3) for a in ("none", "fresh")]
    return jobs


def job_name(job: tuple[str, str, int, int]) -> str:
    mode, arm, n, seed = job
    return f"{mode}-{arm}-N{n}-s{seed}"


def arm_houses(out: Path, arm: str, n: int) -> str:
    """A --houses value for the arm: its preset, or (the oracle) a folder of the oracle presets' first houses."""
    names = ARMS[n][arm]
    if len(names) == 1:
        return f"preset:{names[0]}"
    folder = out / "houses" / f"oracle-N{n}"
    if not (folder / "done").exists():
        folder.mkdir(parents=True, exist_ok=True)
        for name in names:
            for house_name, house in generate_preset(name)[:ORACLE_SHARE[n]]:
                save_house(house, folder / f"{house_name}.json")
        (folder / "done").write_text("", encoding="utf-8")
    return str(folder)


_SETS: dict = {}


def house_set(spec: str):
    """``load_house_set(spec)``, generated and compiled once per process."""
    if spec not in _SETS:
        _SETS[spec] = load_house_set(spec)
    return _SETS[spec]


def say(text: str) -> None:
    print(f"{time.strftime('%H:%M:%S')} {text}", file=sys.stderr, flush=True)


def run_job(out: Path, job: tuple[str, str, int, int]) -> dict:
    """Train, then evaluate one job; returns its result row (also written to OUT/results)."""
    mode, arm, n, seed = job
    name = job_name(job)
    folder = out / "runs" / name
    folder.mkdir(parents=True, exist_ok=True)
    policy = folder / "policy.pt"
    cfg = TrainConfig(houses=arm_houses(out, arm, n), frames=BUDGET, output=str(policy), seed=seed,
                      run_dir=str(folder / "train"), beta_end=0.5, max_episode_steps=600, map=True,
                      teacher="map-explorer", precision="fp32", perception=mode, snapshots=SNAPSHOTS,
                      progress=False, tensorboard=False, eval_every=0,
                      resume=(folder / "train" / "state.pt").exists())
    if not (folder / "policy.json").exists():
        say(f"{name}: training on {cfg.houses} ({'resumed' if cfg.resume else 'from scratch'})")
        train(cfg, command=f"run.py job {name}")
    card = json.loads((folder / "policy.json").read_text(encoding="utf-8"))
    row = {"job": name, "perception": mode, "arm": arm, "n": n, "seed": seed, "houses": cfg.houses,
           "n_train_houses": card["n_houses"], "frames": card["frames"], "train_wall_s": card["wall_time_s"],
           "final_train_success": card["final_train_success"], "validation": {}, "heldout": {}}
    say(f"{name}: trained ({card['wall_time_s']:.0f} s); validation curve")
    for frames_done in sorted(int(p.stem.rsplit("-f", 1)[1]) for p in folder.glob("policy-f*.pt")):
        for set_name, spec in VALIDATION.items():
            rep = evaluate(load_checkpoint(snapshot_path(policy, frames_done)).policy(seed=0), house_set(spec), episodes=VALIDATION_EPISODES, seed=0,
                           with_expert=False)
            row["validation"].setdefault(set_name, {})[str(frames_done)] = rep.summary["success"]
    final = load_checkpoint(policy)
    say(f"{name}: held-out suites")
    for set_name, spec in HELDOUT.items():
        rep = evaluate(final.policy(seed=0), house_set(spec),
                       episodes=HELDOUT_EPISODES, seed=0, with_expert=False)
        row["heldout"][set_name] = {"success": rep.summary["success"], "spl": rep.summary["spl"],
                                    "episodes": rep.summary["episodes"],
                                    "per_episode": [int(r.success) for r in rep.results]}
    say(f"{name}: tail")
    tail = tail_success(final.policy(seed=0),
                        house_set("suite:tail").worlds, per_house=10, fraction=0.1, select_seed=0, score_seed=1)
    row["heldout"]["tail"] = tail.card()
    (out / "results").mkdir(exist_ok=True)
    (out / "results" / f"{name}.json").write_text(json.dumps(row, indent=1) + "\n", encoding="utf-8")
    say(f"{name}: done")
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--jobs", type=int, default=0, help="run at most this many unfinished jobs (0: all)")
    ap.add_argument("--only", nargs="*", default=[], help="job names to run, e.g. shape-none-N24-s0")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "declared.json").write_text(json.dumps(
        {"budget": BUDGET, "snapshots": SNAPSHOTS, "heldout": HELDOUT, "validation": VALIDATION,
         "heldout_episodes": HELDOUT_EPISODES, "validation_episodes": VALIDATION_EPISODES, "arms": ARMS,
         "recipe": asdict(TrainConfig(beta_end=0.5, max_episode_steps=600, map=True, teacher="map-explorer"))},
        indent=1) + "\n", encoding="utf-8")
    todo = [j for j in declared_jobs() if not (args.out / "results" / f"{job_name(j)}.json").exists()]
    if args.only:
        todo = [j for j in todo if job_name(j) in args.only]
    for job in todo[: args.jobs or None]:
        run_job(args.out, job)


if __name__ == "__main__":
    main()
