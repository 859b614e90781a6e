"""Difficulty on request: how close each G brings the agent's success to P, and in how many edits.

    NUMBA_NUM_THREADS=1 nice -n 10 python docs/results/target-success/measure.py OUT.jsonl [HOUSES [STEPS]]
    python docs/results/target-success/measure.py OUT.jsonl table    # the table of the rows already there
    python docs/results/target-success/measure.py summary A.jsonl B.jsonl ...   # every run judged on fresh draws, one line per file and G
    python docs/results/target-success/measure.py stops A.jsonl ...   # +stopK rows: each run against its tolerance_stop
    python docs/results/target-success/measure.py starts A.jsonl ...   # runs within 0.10 on fresh draws, and before any edit
    python docs/results/target-success/measure.py outcomes A.jsonl ...   # how the proposed edits ended, per G

Options (before OUT.jsonl): ``--generators a,b`` (default ``builtin,random,failure-modes``; a name may end in
``+checksK``, the learned G with ``checks=K``, in ``+choicesK``, K edits proposed and measured per round, and in
``+drawsD``, each measured episode run D times with its own sampling seeds, in ``+confirm``, an edit that comes
closer kept only when it also comes closer on confirming draws, and in ``+relocate`` and ``+doors``, the failure-mode
G's ``relocate_targets`` and ``door_edits``, in ``+refresh``, the house measured on new draws after each kept edit,
and in ``+stopK``, editing stopped once the measured gap is at most K
hundredths, the tolerance's own point then also measured: rows carry ``tolerance_stop``, the edits kept and the success
on the measured and on the fresh draws when the gap first came within the tolerance, which is where the run would
have stopped without ``+stopK``),
``--patience N`` (default 3), ``--first K`` (start at the K-th house), ``--rollout-episodes N`` (headings of G's
own rollout check, default 3; rows then carry ``rollout_episodes``), ``--houses SET`` (default
``preset:validation``), ``--targets P,Q`` (default ``0.25,0.5,0.75``), ``--agent SPEC`` (default ``pretrained``; rows
then carry ``agent``).

For every G of ``GENERATORS``, every P of ``TARGETS`` and the first ``N`` houses (the second argument) of ``HOUSES``
(default ``preset:validation``, held out from training), :func:`adaptenv.adapt.target.adapt_to_success` edits the house for the agent
(``pretrained`` unless ``--agent`` names another), measured on ``EPISODES`` seeded episodes, until its success is within ``TOLERANCE`` of P or ``STEPS``
edits are kept or ``PATIENCE`` rounds in a row keep none. One JSON row per run is appended to OUT.jsonl (a rerun skips the runs already there); the
table per (G, P) is printed at the end: houses within 10 points of P, mean edits kept, mean final gap, and the same
on the run's closing check with fresh action draws (rows made before that check show "-").
"""

from __future__ import annotations

import json
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

GENERATORS = ("builtin", "random", "failure-modes")
TARGETS = (0.25, 0.5, 0.75)
EPISODES, TOLERANCE, PATIENCE, SEED, POLICY = 20, 0.10, 3, 0, "pretrained"
FIRST = 0
ROLLOUT_EPISODES = 3
HOUSES = "preset:validation"


def make(g: str):
    """The generator ``g`` names, the choices per round, the draws per episode, whether edits are confirmed, the
    stop gap and whether the house is measured anew after each kept edit (``learned+checks8+choices4+draws3+stop5``:
    the learned G with ``checks=8``, 4 edits measured per round, each episode measured 3 times, editing stopped within
    0.05 of P)."""
    from adaptenv.adapt.generators import make_generator

    name, *mods = g.split("+")
    checks = [int(m.removeprefix("checks")) for m in mods if m.startswith("checks")]
    choices = [int(m.removeprefix("choices")) for m in mods if m.startswith("choices")]
    draws = [int(m.removeprefix("draws")) for m in mods if m.startswith("draws")]
    stop = [int(m.removeprefix("stop")) / 100 for m in mods if m.startswith("stop")]
    kw = {"checks": checks[0]} if checks else {}
    kw |= {"relocate_targets": True} if "relocate" in mods else {}
    kw |= {"door_edits": True} if "doors" in mods else {}
    return (make_generator(name, **kw), (choices or [1])[0], (draws or [1])[0], "confirm" in mods, (stop or [None])[0],
            "refresh" in mods)


def run(out: Path, houses: int, steps: int) -> None:
    """Every (G, P, house) not yet in ``out``: one row each."""
    from adaptenv.adapt.target import adapt_to_success
    from adaptenv.agents.houses import load_house_set
    from adaptenv.agents.network import configure_torch
    from adaptenv.agents.registry import resolve_policy

    configure_torch()
    done = {(r["generator"], r["target"], r["house"]) for r in rows(out)}
    hs = load_house_set(HOUSES)
    policy = resolve_policy(POLICY, seed=SEED)
    for name, house in list(zip(hs.names, hs.houses, strict=True))[FIRST:houses]:  # house by house: a cut run is a subset
        for g in GENERATORS:
            for p in TARGETS:
                if (g, p, name) in done:
                    continue
                t0 = time.perf_counter()
                generator, choices, draws, confirm, stop_gap, refresh = make(g)
                res = adapt_to_success(house, policy, generator, p, tolerance=TOLERANCE, episodes=EPISODES,
                                       max_edits=steps, patience=PATIENCE, seed=SEED, name=name,
                                       rollout_episodes=ROLLOUT_EPISODES, choices=choices, draws=draws,
                                       confirm=confirm, stop_gap=stop_gap, refresh=refresh)
                row = {"generator": g, "target": p, "house": name, "steps": steps, "patience": PATIENCE,
                       "rollout_episodes": ROLLOUT_EPISODES, "choices": choices, "houses": HOUSES, "agent": POLICY, "seconds": time.perf_counter() - t0,
                       **{k: v for k, v in res.to_dict().items() if k not in ("trace", "generator")},
                       "kept_edits": [e.model_dump(mode="json") for e in res.edits], "outcomes": outcomes(res)}
                if stop_gap is not None:
                    row["tolerance_stop"] = tolerance_stop(res, policy, name)
                with out.open("a", encoding="utf-8") as f:
                    f.write(json.dumps(row) + "\n")
                print(f"{g:13s} P={p:.2f} {name}: {res.line()} ({row['seconds']:.0f} s)", flush=True)


def outcomes(res) -> dict[str, int]:
    """How each proposed edit of a run ended: kept (success closer, or SPL only), G made none, invalid, success and
    SPL no closer, success moved away from P, or past it."""
    def kind(r) -> str:
        if r.kept:
            return "kept, success closer" if "closer to" in r.reason else "kept, SPL only"
        for prefix, name in (("G made no edit", "no edit"), ("invalid", "invalid"), ("success unchanged", "no closer"),
                             ("overshoots", "overshoots"), ("moves away", "moves away")):
            if r.reason.startswith(prefix) or prefix in r.reason:
                return name
        return "other"
    return dict(Counter(kind(r) for r in res.rounds))


def tolerance_stop(res, policy, name: str) -> dict:
    """Where the run would have stopped with the tolerance as its stop gap: the edits kept when the measured gap
    first came within the tolerance (every kept edit when it never did: both runs are the same), and the success
    there on the measured and on the run's fresh draws. Until that point the two runs are the same."""
    from adaptenv.adapt.edits import replay
    from adaptenv.adapt.target import fresh_measurement
    from adaptenv.sim.world import compile_world

    trace = res.success_trace
    k = next((i for i, s in enumerate(trace) if abs(s - res.target) <= res.tolerance + 1e-9), len(trace) - 1)
    if k == len(res.edits):
        fresh = res.fresh_after.success
    elif k == 0:
        fresh = res.fresh_before.success
    else:
        world = compile_world(replay(res.original, res.edits[:k]), name)
        fresh = fresh_measurement(world, res.episodes, policy, res.fresh_draws).success
    return {"edits": k, "success": trace[k], "fresh_success": fresh}


def rows(out: Path) -> list[dict]:
    return [json.loads(x) for x in out.read_text(encoding="utf-8").splitlines()] if out.exists() else []


def table(out: Path) -> None:
    """Per (G, P): houses within 10 points, mean edits kept, mean gap, mean success reached."""
    everything = [r for r in rows(out) if r["generator"] in GENERATORS and r["target"] in TARGETS]
    per_house = {h: sum(r["house"] == h for r in everything) for h in {r["house"] for r in everything}}
    full = len(GENERATORS) * len(TARGETS)
    rs = [r for r in everything if per_house[r["house"]] == full]  # houses with every (G, P) run
    print(f"{len(per_house)} house(s) run, {sum(n == full for n in per_house.values())} with every (G, P) "
          "(the table counts these)")
    print("| G | P | houses within 0.10 | of them within before any edit | mean edits kept | mean gap | "
          "mean success reached | mean wall s per run | within 0.10 on fresh draws | mean fresh success before, reached |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for g in GENERATORS:
        for p in TARGETS:
            sel = [r for r in rs if r["generator"] == g and r["target"] == p]
            if not sel:
                continue
            within = sum(r["gap"] <= 0.10 + 1e-9 for r in sel)
            already = sum(abs(r["success_before"] - p) <= 0.10 + 1e-9 for r in sel)
            print(f"| {g} | {p:.2f} | {within}/{len(sel)} | {already} | {np.mean([r['edits'] for r in sel]):.1f} | "
                  f"{np.mean([r['gap'] for r in sel]):.3f} | {np.mean([r['success'] for r in sel]):.3f} | "
                  f"{np.mean([r['seconds'] for r in sel]):.0f} | {fresh(sel, p)} |")
    start = {r["house"]: r["success_before"] for r in rs if r["generator"] == GENERATORS[0]}
    print(f"\nsuccess before any edit with {GENERATORS[0]}'s measurement, per house: "
          f"{', '.join(f'{h} {s:.2f}' for h, s in sorted(start.items()))}")


def fresh(sel: list[dict], p: float) -> str:
    """The runs' fresh check (houses within 0.10 of P on fresh draws; mean success before and reached), or "-"
    for rows made before it existed."""
    if not all(r.get("fresh_success") is not None for r in sel):
        return "- | -"
    return (f"{fresh_within(sel, p)}/{len(sel)} | {np.mean([r['fresh_success_before'] for r in sel]):.3f}, "
            f"{np.mean([r['fresh_success'] for r in sel]):.3f}")


def near(v: float, p: float) -> bool:
    """Whether a success rate lies within 0.10 of P."""
    return abs(v - p) <= 0.10 + 1e-9


def fresh_within(sel: list[dict], p: float) -> int:
    """How many of the runs ended within 0.10 of P on their fresh draws."""
    return sum(near(r["fresh_success"], p) for r in sel)


def summary(files: list[Path]) -> None:
    """One line per (rows file, G) with a fresh check: houses, runs within 0.10 of P on fresh draws per P, and the mean
    fresh success before and reached (the rows' own settings: see each run's section of the README)."""
    print("| rows | G | houses | budget, patience | within 0.10 on fresh draws (P = 0.25 / 0.5 / 0.75) | "
          "mean fresh success before, reached | fresh drop (points) |")
    print("|---|---|---|---|---|---|---|")
    for f in files:
        rs = [r for r in rows(f) if r.get("fresh_success") is not None]
        for g in dict.fromkeys(r["generator"] for r in rs):
            sel = [r for r in rs if r["generator"] == g]
            names = sorted({r["house"] for r in sel})
            per_p = " / ".join(
                f"{fresh_within(ps, p)}/{len(ps)}" if ps else "-"
                for p in (0.25, 0.5, 0.75) for ps in [[r for r in sel if r["target"] == p]])
            before, after = np.mean([r["fresh_success_before"] for r in sel]), np.mean([r["fresh_success"] for r in sel])
            print(f"| {f.name} | {g} | {names[0]} to {names[-1]} ({len(names)}) | "
                  f"{'/'.join(str(v) for v in sorted({r['steps'] for r in sel}))}, "
                  f"{'/'.join(str(v) for v in sorted({r['patience'] for r in sel}))} | {per_p} | "
                  f"{before:.3f}, {after:.3f} | {100 * (before - after):.1f} |")


def starts(files: list[Path]) -> None:
    """Per (G, P): runs within 0.10 of P on fresh draws at the end, how many of those already were before any edit,
    and how many runs started within it on fresh draws at all."""
    rs = [r for f in files for r in rows(f) if r.get("fresh_success") is not None]
    print("| G | P | runs | within 0.10 on fresh draws at the end | of them within before any edit | "
          "within 0.10 on fresh draws before any edit |")
    print("|---|---|---|---|---|---|")
    for g in dict.fromkeys(r["generator"] for r in rs):
        for p in sorted({r["target"] for r in rs if r["generator"] == g}):
            sel = [r for r in rs if r["generator"] == g and r["target"] == p]
            end = [r for r in sel if near(r["fresh_success"], p)]
            print(f"| {g} | {p:.2f} | {len(sel)} | {len(end)} | {sum(near(r['fresh_success_before'], p) for r in end)} | "
                  f"{sum(near(r['fresh_success_before'], p) for r in sel)} |")


def outcome_table(files: list[Path]) -> None:
    """Per G: how the proposed edits of its runs ended (rows that record ``outcomes``), as counts and shares."""
    rs = [r for f in files for r in rows(f) if "outcomes" in r]
    kinds = sorted({k for r in rs for k in r["outcomes"]})
    print("| G | runs | edits proposed | " + " | ".join(kinds) + " |")
    print("|---|---|---|" + "---|" * len(kinds))
    for g in dict.fromkeys(r["generator"] for r in rs):
        total = Counter()
        for r in rs:
            total.update(r["outcomes"] if r["generator"] == g else {})
        n = sum(total.values())
        print(f"| {g} | {sum(r['generator'] == g for r in rs)} | {n} | "
              + " | ".join(f"{total[k]} ({100 * total[k] / max(n, 1):.0f}%)" for k in kinds) + " |")


def stops(files: list[Path]) -> None:
    """Per P, the ``+stopK`` runs within 0.10 of P on their own and on fresh draws, against the same runs where the
    tolerance alone would have stopped them (``tolerance_stop``), with the mean edits kept and fresh success."""
    rs = [r for f in files for r in rows(f) if "tolerance_stop" in r]
    print("| P | runs | stop gap: within 0.10 (own draws / fresh draws) | tolerance stop: within 0.10 (own / fresh) | "
          "mean edits kept (stop gap / tolerance stop) | mean fresh success reached (stop gap / tolerance stop) |")
    print("|---|---|---|---|---|---|")
    for p in sorted({r["target"] for r in rs}):
        sel = [r for r in rs if r["target"] == p]
        ts = [r["tolerance_stop"] for r in sel]
        print(f"| {p:.2f} | {len(sel)} | {sum(near(r['success'], p) for r in sel)} / "
              f"{sum(near(r['fresh_success'], p) for r in sel)} | "
              f"{sum(near(t['success'], p) for t in ts)} / {sum(near(t['fresh_success'], p) for t in ts)} | "
              f"{np.mean([r['edits'] for r in sel]):.1f} / {np.mean([t['edits'] for t in ts]):.1f} | "
              f"{np.mean([r['fresh_success'] for r in sel]):.3f} / {np.mean([t['fresh_success'] for t in ts]):.3f} |")
    both = sum(near(r["fresh_success"], r["target"]) for r in rs)
    tol = sum(near(r["tolerance_stop"]["fresh_success"], r["target"]) for r in rs)
    print(f"\nwithin 0.10 of P on fresh draws: {both} of {len(rs)} runs with the stop gap, {tol} at their tolerance stop")


if __name__ == "__main__":
    reports = {"summary": summary, "stops": stops, "outcomes": outcome_table, "starts": starts}
    if sys.argv[1] in reports:  # `measure.py REPORT A.jsonl B.jsonl ...`
        reports[sys.argv[1]]([Path(a) for a in sys.argv[2:]])
        sys.exit(0)
    while sys.argv[1].startswith("--"):  # --generators a,b / --patience N / --first K
        flag, value = sys.argv.pop(1), sys.argv.pop(1)
        if flag == "--generators":
            GENERATORS = tuple(value.split(","))
        elif flag == "--patience":
            PATIENCE = int(value)
        elif flag == "--first":
            FIRST = int(value)
        elif flag == "--rollout-episodes":
            ROLLOUT_EPISODES = int(value)
        elif flag == "--houses":
            HOUSES = value
        elif flag == "--targets":
            TARGETS = tuple(float(t) for t in value.split(","))
        elif flag == "--agent":
            POLICY = value
        else:
            sys.exit(f"unknown option {flag}")
    target = Path(sys.argv[1])
    if sys.argv[2:3] != ["table"]:  # `measure.py OUT.jsonl table` prints the table of the rows already there
        run(target, int(sys.argv[2]) if len(sys.argv) > 2 else 10, int(sys.argv[3]) if len(sys.argv) > 3 else 8)
    table(target)
