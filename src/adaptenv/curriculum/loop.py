"""The closed loop, t = 1..T: evaluate pi_t on its training scenes, make e_{t+1}, fine-tune, measure held-out.

One function, :func:`run_loop`, reads top to bottom (CleanRL style) and runs any method of
:data:`METHODS` under the same explicit budgets:

- ``none``: no new scenes; fine-tune on the original training scenes.
- ``random``: ``edit_steps`` random single-object edits of each selected training scene.
- ``dr``: domain randomization, fresh procedural houses.
- ``plr``: Robust PLR; fresh procedural houses are only scored (regret), gradient steps are taken
  on levels replayed from a prioritized buffer.
- ``accel``: ACCEL; replayed high-regret levels get ``edit_steps`` random edits each, the children
  are scored and inserted; gradient steps on replayed levels only.
- ``ours``: the paper's method with the built-in F and G (analysis -> objective-driven edits).
- ``ours-llm``: the same with LLM F and G (needs an LLM config).

Per iteration every method rolls out the same number of analysis/scoring episodes, spends the same
number of fine-tuning frames (hence the same gradient updates), and the editing methods make
``edit_steps`` edits per adapted scene. Environment steps and updates are counted and logged.
Every iteration is checkpointed atomically; ``resume=True`` continues from the last finished one
and ends with the same results as an uninterrupted run (all randomness derives from (seed, t)).
"""

from __future__ import annotations

import json
import shutil
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from adaptenv.adapt.llm.accounting import check_llm_section, same_run, scenes_usage
from adaptenv.curriculum import buffer as lb
from adaptenv.curriculum.llm_usage import budget_left, iteration_lines, record_iteration
from adaptenv.curriculum.records import (
    STATE,
    GalleryItem,
    IterationRecord,
    RunInfo,
    SetMetrics,
    atomic_write_text,
    iteration_dir,
    read_iterations,
    write_iterations,
)
from adaptenv.errors import ConfigError

METHODS = ("none", "random", "dr", "plr", "accel", "ours", "ours-llm")
EDITING = ("random", "accel", "ours", "ours-llm")


@dataclass
class LoopConfig:
    """Settings of one closed-loop run (one method, one seed); saved as run.json."""

    method: str = "ours"
    """One of none, random, dr, plr, accel, ours, ours-llm."""
    policy: str = "pretrained"
    """Starting policy pi_0: pretrained or a checkpoint path (it must be a neural policy to fine-tune)."""
    houses: str = "preset:pretrain-train"
    """Training scenes e_0: a folder of house JSON files or preset:NAME."""
    heldout: dict[str, str] = field(default_factory=lambda: {"rearranged": "preset:pretrain-rearranged",
                                                             "unseen": "preset:pretrain-unseen"})
    """Held-out sets, never trained on: name -> folder or preset:NAME."""
    iterations: int = 3
    """Loop iterations T."""
    seed: int = 0
    """Root seed; every random choice derives from (seed, iteration)."""
    scenes_per_iteration: int = 8
    """Scenes rolled out (analysed or scored) and new scenes made per iteration."""
    edit_steps: int = 5
    """Single-object edits per adapted scene (editing methods)."""
    finetune_frames: int = 16_384
    """Labelled frames of DAgger fine-tuning per iteration (identical for every method)."""
    finetune_envs: int = 64
    """Parallel agents while fine-tuning."""
    finetune_lr: float = 1e-4
    """Adam learning rate of fine-tuning, annealed to zero over each iteration's frames (the gentler of
    the two rates compared in docs/RESULTS.md)."""
    replay_fraction: float = 0.5
    """Share of the fine-tuning scenes drawn from earlier scenes so the policy does not forget."""
    heldout_episodes: int = 100
    """Episodes per held-out set per evaluation (the same episodes every iteration)."""
    gallery: int = 4
    """Adapted scenes per iteration kept with before/after renders for the report."""
    llm: dict[str, Any] = field(default_factory=dict)
    """LLMConfig fields for ours-llm (provider, model, base_url, api, cache_dir, prompts, price_in, price_out,
    max_tokens, max_cost, ...; docs/llm.md). Never an API key: name its variable in api_key_env."""
    buffer_capacity: int = 64
    """Level buffer size (plr, accel)."""

    def check(self) -> LoopConfig:
        """Return self or raise one ConfigError naming the field and the fix."""
        if self.method not in METHODS:
            raise ConfigError(f"loop config: method {self.method!r} is unknown; use one of {', '.join(METHODS)}")
        for name in ("iterations", "scenes_per_iteration", "finetune_frames", "heldout_episodes", "finetune_envs"):
            if getattr(self, name) < 1:
                raise ConfigError(f"loop config: {name} must be at least 1, got {getattr(self, name)}")
        if self.edit_steps < 0 or not 0.0 <= self.replay_fraction < 1.0:
            raise ConfigError("loop config: edit_steps must be >= 0 and replay_fraction in [0, 1)")
        if self.method == "ours-llm" and not self.llm:
            raise ConfigError("loop config: method ours-llm needs an llm section (provider, model, base_url); "
                              "see docs/llm.md")
        check_llm_section(self.llm, "loop config: llm")
        return self


@dataclass
class LoopState:
    """Where a run stands after a finished iteration (state.json); scenes live in RUN_DIR/scenes/."""

    iteration: int = 0
    pool: list[str] = field(default_factory=list)
    """Current training scenes (names), the ones the next iteration rolls out and adapts."""
    archive: list[str] = field(default_factory=list)
    """Every training scene made so far, originals first (replay mix draws from it)."""
    buffer: dict[str, Any] | None = None
    env_steps: int = 0
    grad_updates: int = 0
    edits: int = 0
    generated: int = 0


class SceneStore:
    """Scenes of a run by name, on disk (RUN_DIR/scenes/NAME.json) with an in-memory cache."""

    def __init__(self, root: Path):
        self.root = root
        self.root.mkdir(parents=True, exist_ok=True)
        self._houses: dict[str, Any] = {}
        self._worlds: dict[str, Any] = {}

    def put(self, name: str, house: Any) -> str:
        from adaptenv.scene.house import save_house

        save_house(house, self.root / f"{name}.json")
        self._houses[name] = house
        self._worlds.pop(name, None)
        return name

    def house(self, name: str) -> Any:
        if name not in self._houses:
            from adaptenv.scene.house import load_house

            self._houses[name] = load_house(self.root / f"{name}.json", validate=False)
        return self._houses[name]

    def world(self, name: str) -> Any:
        if name not in self._worlds:
            from adaptenv.sim.world import compile_world

            self._worlds[name] = compile_world(self.house(name), name)
        return self._worlds[name]


def _rng(seed: int, t: int, purpose: int) -> np.random.Generator:
    """The generator for one purpose of one iteration: independent of everything else."""
    return np.random.default_rng([seed, t, purpose])


def _set_metrics(results: list[Any]) -> SetMetrics:
    from adaptenv.agents.evaluate import mean_se

    s, s_se = mean_se([float(r.success) for r in results])
    spl, spl_se = mean_se([r.spl for r in results])
    col, _ = mean_se([float(r.collisions) for r in results])
    return SetMetrics(success=s, spl=spl, collisions=col, episodes=len(results), success_se=s_se, spl_se=spl_se)


def rollout_scenes(store: SceneStore, names: list[str], weights: Any, seed: int, executor: Any
                   ) -> tuple[list[Any], list[Any]]:
    """One episode of the policy in each named scene: results and trajectories (with metrics)."""
    from adaptenv.curriculum.jobs import RolloutJob, run_rollout

    jobs = [RolloutJob(weights, store.house(n), n, int(np.random.SeedSequence([seed, i]).generate_state(1)[0]))
            for i, n in enumerate(names)]
    pairs = executor.map(run_rollout, jobs, desc="rollouts")
    return [r for r, _ in pairs], [traj for _, traj in pairs]


def evaluate_sets(weights: Any, specs: dict[str, str], episodes: int, seed: int, executor: Any) -> dict[str, SetMetrics]:
    """Held-out figures of a policy on each set, on the same episodes every call (paired comparisons)."""
    from adaptenv.curriculum.jobs import eval_jobs, run_eval

    tagged = eval_jobs(weights, specs, episodes, seed)
    chunks = executor.map(run_eval, [job for _, job in tagged], desc="held-out evaluation")
    return {name: _set_metrics([r for (n, _), rs in zip(tagged, chunks, strict=True) if n == name for r in rs])
            for name in specs}


def _finetune(net: Any, worlds: list[Any], cfg: LoopConfig, seed: int) -> tuple[Any, dict[str, Any]]:
    """DAgger fine-tuning for ``cfg.finetune_frames`` frames; returns the new network and its card."""
    from adaptenv.agents.config import TrainConfig
    from adaptenv.agents.train import train

    steps = 32
    tc = TrainConfig(houses="(in memory)", frames=cfg.finetune_frames, output="", seed=seed, num_envs=cfg.finetune_envs,
                     rollout_steps=steps, chunk_len=steps, batch_chunks=64, updates_per_iter=4,
                     buffer_frames=max(cfg.finetune_frames, steps * cfg.finetune_envs), beta_start=0.8, beta_end=0.8,
                     eval_every=0, final_eval_episodes=len(worlds), progress=False, tensorboard=False,
                     learning_rate=cfg.finetune_lr, save_every=10**9)
    result = train(tc, worlds=worlds, init_net=net)
    return result.net, result.card


def _gallery_item(run_dir: Path, t: int, name: str, parent: Any, child: Any, traj: Any, analysis: Any,
                  edits: Any) -> GalleryItem:
    """Write before/after renders, the analysis and the edit log of one adapted scene."""
    from adaptenv.render.topdown import render_house

    d = iteration_dir(run_dir, t) / "gallery" / name
    d.mkdir(parents=True, exist_ok=True)
    moved = {e.object_id: "#e6194b" for e in (edits.edits if edits is not None else []) if e.accepted and e.changed}
    render_house(parent, trajectory=traj, grid=True, size=640).save(d / "before.png")
    render_house(child, trajectory=traj, grid=True, size=640, highlight=moved or None).save(d / "after.png")
    item = GalleryItem(scene=name, before_png=str((d / "before.png").relative_to(run_dir)),
                       after_png=str((d / "after.png").relative_to(run_dir)))
    if analysis is not None:
        (d / "analysis.json").write_text(analysis.model_dump_json(indent=1), encoding="utf-8")
        item.analysis_json = str((d / "analysis.json").relative_to(run_dir))
        item.summary = analysis.outcome.summary
    if edits is not None:
        (d / "edits.json").write_text(edits.model_dump_json(indent=1), encoding="utf-8")
        item.edits_json = str((d / "edits.json").relative_to(run_dir))
    return item


def _fresh_houses(store: SceneStore, state: LoopState, seed: int, t: int, k: int) -> list[str]:
    """``k`` new procedural houses (domain randomization), named ``drNNNN`` and stored."""
    from adaptenv.scene.procedural import generate_house

    out = []
    for _ in range(k):
        house_seed = int(np.random.SeedSequence([seed, t, 3, state.generated]).generate_state(1)[0]) % 2**31
        out.append(store.put(f"dr{state.generated:04d}", generate_house(house_seed)))
        state.generated += 1
    return out


def run_loop(cfg: LoopConfig, run_dir: str | Path, *, resume: bool = False, executor: Any = None,
             progress: Any = None, command: str = "") -> list[IterationRecord]:
    """Run (or resume) one method for ``cfg.iterations`` iterations; returns every iteration's record.

    Rollouts, held-out evaluation and scene generation go through ``executor`` (in process when
    None; see :mod:`adaptenv.curriculum.executor`); every executor gives the same results.
    ``progress(text)`` is called with one line per finished stage.
    """
    from adaptenv.agents.checkpoint import load_checkpoint, save_checkpoint
    from adaptenv.agents.houses import load_house_set
    from adaptenv.agents.registry import resolve_policy
    from adaptenv.curriculum.executor import InProcessExecutor
    from adaptenv.curriculum.jobs import GenerateJob, PolicyWeights, run_generate
    cfg.check()
    run_dir = Path(run_dir)
    say = progress or (lambda text: None)
    state_path = run_dir / STATE
    if resume and state_path.is_file():
        saved = json.loads(state_path.read_text(encoding="utf-8"))
        if not same_run(saved.get("config"), asdict(cfg)):
            raise ConfigError(f"{run_dir}: --resume with a different config than the interrupted run; "
                              "use the same config or a new output folder")
        state = LoopState(**saved["state"])
        records = read_iterations(run_dir)[: state.iteration + 1]
    else:
        if run_dir.exists() and any(run_dir.iterdir()) and not resume:
            raise ConfigError(f"{run_dir}: the output folder is not empty; pass --resume to continue it or "
                              "choose a new folder")
        run_dir.mkdir(parents=True, exist_ok=True)
        state, records = LoopState(), []
    info = run_dir / "run.json"
    if resume and info.is_file():  # keep the command that started the run
        command = RunInfo.model_validate_json(info.read_text(encoding="utf-8")).command or command
    atomic_write_text(info, RunInfo(method=cfg.method, seed=cfg.seed, config=asdict(cfg),
                                    command=command).model_dump_json(indent=1))
    store = SceneStore(run_dir / "scenes")
    ex = executor if executor is not None else InProcessExecutor()
    bcfg = lb.LevelBufferConfig(capacity=cfg.buffer_capacity, min_fill=0.0, replay_prob=1.0).check()

    if state.iteration == 0 and not records:
        base = load_house_set(cfg.houses)
        state.pool = [store.put(n, h) for n, h in zip(base.names, base.houses, strict=True)]
        state.archive = list(state.pool)
        policy = resolve_policy(cfg.policy, seed=cfg.seed)
        if not hasattr(policy, "net"):
            raise ConfigError(f"--policy {cfg.policy!r} is not a neural policy; the loop fine-tunes, so pass "
                              "pretrained or a checkpoint path")
        save_checkpoint(iteration_dir(run_dir, 0) / "policy.pt", policy.net, {"iteration": 0})
        say("evaluating pi_0 on the held-out sets")
        records = [IterationRecord(iteration=0, env_steps=0, grad_updates=0, edits=0,
                                   heldout=evaluate_sets(PolicyWeights.of(policy.net), cfg.heldout,
                                                         cfg.heldout_episodes, cfg.seed, ex))]
        _checkpoint(run_dir, cfg, state, records)
    n = cfg.scenes_per_iteration

    for t in range(state.iteration + 1, cfg.iterations + 1):
        if why := budget_left(run_dir, cfg.llm):  # stop cleanly; raise the budget and --resume to go on
            say(f"stopping before t={t}: {why}")
            break
        start = time.perf_counter()
        llm_usage = None
        net = load_checkpoint(iteration_dir(run_dir, t - 1) / "policy.pt").net
        weights = PolicyWeights.of(net)
        shutil.rmtree(iteration_dir(run_dir, t), ignore_errors=True)  # a killed attempt at t starts over
        buf = lb.LevelBufferState.from_dict(state.buffer) if state.buffer else lb.empty_state()
        new: list[str] = []
        gallery: list[GalleryItem] = []
        edits_before = state.edits

        # 1. roll pi_t out in the scenes this method looks at (analysis or scoring)
        seeding = cfg.method in ("plr", "accel") and buf.size == 0
        plans: list[lb.ChildPlan] = []
        if seeding:
            rolled = state.pool[:]  # seed the buffer with the original training scenes
        elif cfg.method == "plr":
            rolled = _fresh_houses(store, state, cfg.seed, t, n)
        elif cfg.method == "accel":
            idx = lb.sample_replay(buf, bcfg, _rng(cfg.seed, t, 1), t, k=n)
            replayed = [buf.level_ids[i] for i in idx]  # gradient steps go to these parents
            buf = lb.update_scores(buf, list(idx), [buf.scores[i] for i in idx], t)
            plans = lb.select_parents(buf, idx, _rng(cfg.seed, t, 2))
            made = ex.map(run_generate, [GenerateJob("random", store.house(p.parent_id), p.parent_id, cfg.edit_steps,
                                                     (p.seed,)) for p in plans], desc="ACCEL edits")
            rolled = []
            for k, (plan, g) in enumerate(zip(plans, made, strict=True)):
                name = store.put(f"{plan.parent_id.split('~')[0]}~t{t:02d}c{k:02d}", g.house)
                state.edits += g.edits
                rolled.append(name)
                if len(gallery) < cfg.gallery:
                    gallery.append(_gallery_item(run_dir, t, name, store.house(plan.parent_id), g.house, None, None,
                                                 g.edit_log))
        elif cfg.method == "dr":
            rolled = _fresh_houses(store, state, cfg.seed, t, n)
        else:
            first = (t - 1) * n % len(state.pool)
            rolled = [state.pool[(first + k) % len(state.pool)] for k in range(min(n, len(state.pool)))]
        say(f"t={t}: rolling out pi_{t - 1} in {len(rolled)} scenes")
        results, trajs = rollout_scenes(store, rolled, weights,
                                        int(np.random.SeedSequence([cfg.seed, t, 4]).generate_state(1)[0]), ex)
        state.env_steps += sum(r.steps for r in results)
        train_metrics = _set_metrics(results)

        # 2. the method's new training scenes e_{t+1}
        if cfg.method in ("plr", "accel"):
            scores = [lb.regret_score(float(r.success), r.spl, 1.0) for r in results]
            parents = [p.parent_id for p in plans] if plans else [None] * len(rolled)
            for name, score, parent in zip(rolled, scores, parents, strict=True):
                buf = lb.insert(buf, bcfg, name, score, t, parent_id=parent)
            if plans:  # ACCEL trains on the replayed parents; their children were only scored
                train_names = replayed
            else:  # plr, and accel's first iteration: replay from the buffer just filled
                replay = lb.sample_replay(buf, bcfg, _rng(cfg.seed, t, 5), t, k=n)
                train_names = [buf.level_ids[i] for i in replay]
                buf = lb.update_scores(buf, list(replay), [buf.scores[i] for i in replay], t)
        elif cfg.method == "none":
            train_names = list(state.pool)
        else:
            if cfg.method == "dr":
                new = rolled
            else:  # random edits, or the paper's analysis F then generator G (ours, ours-llm)
                kind, tag = ("random", "r") if cfg.method == "random" else (cfg.method, "a")
                jobs = [GenerateJob(kind, store.house(name), name, cfg.edit_steps, (cfg.seed, t, 100 + k),
                                    trajectory=traj, llm=cfg.llm)
                        for k, (name, traj) in enumerate(zip(rolled, trajs, strict=True))]
                made = ex.map(run_generate, jobs, desc="generation")
                if cfg.method == "ours-llm":
                    llm_usage = record_iteration(run_dir, t, scenes_usage(made), cfg.llm).iterations[str(t)]
                    for line in iteration_lines(t, rolled, made, run_dir, cfg.llm):
                        say(line)
                for k, (name, g) in enumerate(zip(rolled, made, strict=True)):
                    state.edits += g.edits
                    new.append(store.put(f"{name.split('~')[0]}~t{t:02d}{tag}{k:02d}", g.house))
                    if len(gallery) < cfg.gallery:
                        gallery.append(_gallery_item(run_dir, t, new[-1], store.house(name), g.house, trajs[k],
                                                     g.analysis, g.edit_log))
            if cfg.method in EDITING:  # adapted scenes replace their parents in the pool
                pool = list(state.pool)
                for parent, child in zip(rolled, new, strict=True):
                    pool[pool.index(parent)] = child
                state.pool = pool
            fresh_names = [x for x in new if x not in state.archive]
            n_replay = int(round(len(new) * cfg.replay_fraction / (1.0 - cfg.replay_fraction)))
            earlier = state.archive
            pick = _rng(cfg.seed, t, 6).choice(len(earlier), size=min(n_replay, len(earlier)), replace=False)
            train_names = new + [earlier[i] for i in sorted(pick.tolist())]
            state.archive = state.archive + fresh_names

        # 3. fine-tune pi on the new scenes with expert labels
        say(f"t={t}: fine-tuning on {len(train_names)} scenes ({cfg.finetune_frames} frames)")
        net, card = _finetune(net, [store.world(x) for x in train_names], cfg,
                              int(np.random.SeedSequence([cfg.seed, t, 7]).generate_state(1)[0] % 2**31))
        state.env_steps += int(card["frames"])
        state.grad_updates += int(card["updates"])
        save_checkpoint(iteration_dir(run_dir, t) / "policy.pt", net, {"iteration": t, "method": cfg.method})

        # 4. held-out evaluation of pi_{t+1}
        say(f"t={t}: evaluating on the held-out sets")
        heldout = evaluate_sets(PolicyWeights.of(net), cfg.heldout, cfg.heldout_episodes, cfg.seed, ex)
        state.buffer = buf.to_dict() if cfg.method in ("plr", "accel") else None
        state.iteration = t
        records.append(IterationRecord(iteration=t, env_steps=state.env_steps, grad_updates=state.grad_updates,
                                       edits=state.edits, train=train_metrics, heldout=heldout, gallery=gallery,
                                       wall_time_s=round(time.perf_counter() - start, 2), llm_usage=llm_usage))
        (iteration_dir(run_dir, t) / "scenes.json").write_text(json.dumps(
            {"rolled_out": rolled, "trained_on": train_names, "edits_this_iteration": state.edits - edits_before}),
            encoding="utf-8")
        _checkpoint(run_dir, cfg, state, records)
    return records


def _checkpoint(run_dir: Path, cfg: LoopConfig, state: LoopState, records: list[IterationRecord]) -> None:
    """Write the iteration log, then the resume state (last, atomically)."""
    write_iterations(run_dir, records)
    atomic_write_text(run_dir / STATE, json.dumps({"config": asdict(cfg), "state": asdict(state)}, indent=1))
