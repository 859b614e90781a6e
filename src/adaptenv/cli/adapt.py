"""``adaptenv analyze`` (F on a recorded episode), ``adaptenv adapt`` (one closed-loop step), ``adaptenv audit``
(the plausibility audit of an adapted house), ``adaptenv bench adapt`` and ``adaptenv bench plausibility``.

Commands import their dependencies when they run, so ``adaptenv --help`` stays fast and never loads
torch or numba.
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import typer

from adaptenv.cli import _numbers as numbers
from adaptenv.cli._common import HOUSE_HELP, JSON_OPTION, load_house_argument
from adaptenv.cli._outputs import FORCE_OPTION, output_folder
from adaptenv.errors import AdaptenvError, ConfigError, PolicyError
from adaptenv.files import atomic_write_text

if TYPE_CHECKING:
    from adaptenv.sim.trajectory import Trajectory
    from adaptenv.sim.world import NavWorld

log = logging.getLogger(__name__)

ADAPT_HOUSE_ARGUMENT = typer.Argument(..., metavar="HOUSE", show_default=False,
                                      help="House JSON file (ProcTHOR format), or a folder of them or a dataset "
                                           "FILE.jsonl[.gz][:START:STOP] (each house adapted into OUT/NAME/; houses "
                                           "that cannot be used are skipped).")
HOUSE_ARGUMENT = typer.Argument(..., metavar="HOUSE", help=HOUSE_HELP, show_default=False)
TRAJ_ARGUMENT = typer.Argument(..., metavar="TRAJ.json", help="Trajectory JSON (from `adaptenv rollout -o` or "
                               "`adaptenv trajectory from-ai2thor`).",
                               show_default=False)
MODEL_OPTION = typer.Option(None, "--model", help="LLM model name (default gpt-4.1-mini, the paper's model).")
BASE_URL_OPTION = typer.Option(None, "--base-url", metavar="URL",
                               help="Server URL ending in /v1 (OpenAI, vLLM, Ollama, llama.cpp); default "
                                    "$OPENAI_BASE_URL, else the OpenAI API (then OPENAI_API_KEY must be set).")
API_OPTION = typer.Option(None, "--api", help="responses (the paper's) or chat (Chat Completions); default: "
                          "responses for the OpenAI API, chat for any other --base-url.")
KEY_ENV_OPTION = typer.Option(None, "--api-key-env", metavar="VAR", help="Environment variable holding the key "
                              "(default OPENAI_API_KEY for OpenAI, ADAPTENV_LLM_API_KEY for other servers).")
OUT_OPTION = typer.Option(..., "-o", "--out", help="Folder for the adapted house, renders and logs.")
CACHE_OPTION = typer.Option(None, "--llm-cache", metavar="DIR", help="Cache LLM answers in this folder; a rerun "
                            "with the same inputs makes no request.")
PROMPTS_OPTION = typer.Option(None, "--prompts", help="adaptenv (default, richer prompts) or paper (the paper's "
                              "appendix prompts verbatim).")
PRICE_IN_OPTION = typer.Option(None, "--price-in", min=0.0, callback=numbers.finite, metavar="USD", help="USD per million input tokens "
                               "(cost estimates; gpt-4.1-mini: see docs/llm.md).")
PRICE_OUT_OPTION = typer.Option(None, "--price-out", min=0.0, callback=numbers.finite, metavar="USD",
                                help="USD per million output tokens.")
MAX_TOKENS_OPTION = typer.Option(None, "--max-tokens", min=1, help="Token budget (input + output) of the run; "
                                 "G stops cleanly when it is used up.")
MAX_COST_OPTION = typer.Option(None, "--max-cost", min=0.0, callback=numbers.finite, metavar="USD", help="Cost budget of the run in USD "
                               "(needs --price-in and --price-out).")
TARGET_MOVES_OPTION = typer.Option(False, "--allow-target-moves", help="Let the LLM G move the episode's target "
                                   "objects (excluded by default, like the built-in G).")
TARGET_CHOICES_OPTION = typer.Option(1, "--target-choices", min=1, max=64, metavar="K", help="With "
                                     "--target-success: edits G proposes per round, each measured; the closest "
                                     "to P is kept.")
TARGET_DRAWS_OPTION = typer.Option(1, "--target-draws", min=1, max=16, metavar="D", help="With --target-success: "
                                   "action draws per measured episode, each with its own sampling seed (less noise "
                                   "in each measurement, D times the rollouts).")
TARGET_STOP_GAP_OPTION = typer.Option(None, "--target-stop-gap", callback=numbers.finite, metavar="G", help="With "
                                      "--target-success: stop editing once |success - P| is at most G (0 to the "
                                      "tolerance; default half the tolerance); P counts as reached within the "
                                      "tolerance.")
LLM_CONFIG_OPTION = typer.Option(None, "--llm-config", metavar="FILE", help="LLMConfig JSON file (docs/llm.md); "
                                 "the flags above override its fields.")


def llm_config(model: str | None, base_url: str | None, cache_dir: Path | None, what: str, *,
               api: str | None = None, api_key_env: str | None = None, prompts: str | None = None, price_in: float | None = None,
               price_out: float | None = None, max_tokens: int | None = None, max_cost: float | None = None,
               allow_target_moves: bool = False, config_file: Path | None = None):
    """The LLMConfig the flags describe; one-line errors when no server is configured or a value is wrong."""
    from pydantic import ValidationError

    from adaptenv.adapt.llm import LLMConfig, load_llm_config
    from adaptenv.adapt.llm.config import BASE_URL_ENV, OPENAI_BASE_URL

    base = load_llm_config(config_file).model_dump(exclude_defaults=True) if config_file is not None else {}
    url = base_url or base.get("base_url")
    if url is None and not os.environ.get(BASE_URL_ENV) and not os.environ.get(
            api_key_env or base.get("api_key_env") or "OPENAI_API_KEY"):
        raise ConfigError(f"{what} needs a model server: set OPENAI_API_KEY for the OpenAI API, or pass "
                          "--base-url http://localhost:11434/v1 (any OpenAI-compatible server)")
    if base_url is not None:
        base["provider"] = "openai" if base_url.rstrip("/") == OPENAI_BASE_URL else "openai-compatible"
    flags = {"model": model, "base_url": base_url, "cache_dir": cache_dir, "api": api, "api_key_env": api_key_env,
             "prompts": prompts, "price_in": price_in, "price_out": price_out, "max_tokens": max_tokens,
             "max_cost": max_cost, "allow_target_moves": allow_target_moves or None}
    fields = {**base, **{k: v for k, v in flags.items() if v is not None}}
    try:
        cfg = LLMConfig(**fields)
        cfg.budget()
    except ValidationError as exc:
        err = exc.errors(include_url=False, include_input=False)[0]
        raise ConfigError(f"{what}: LLM setting {'.'.join(map(str, err['loc']))}: {err['msg']}; fix the flag "
                          "or the --llm-config file") from None
    return cfg


def check_llm_config(config_file: Path | None) -> None:
    """Read ``--llm-config`` whenever it is given, so a broken file is one line even where no LLM runs."""
    if config_file is not None:
        from adaptenv.adapt.llm import load_llm_config

        load_llm_config(config_file)


def llm_backend(model: str | None, base_url: str | None, cache_dir: Path | None, what: str, **kw):
    """An LLM backend for ``what`` (e.g. '--generator llm'); see :func:`llm_config` for the options."""
    from adaptenv.adapt.llm import make_backend

    return make_backend(llm_config(model, base_url, cache_dir, what, **kw))


def load_trajectory_in(trajectory: Path, world: NavWorld, house: Path) -> Trajectory:
    """The trajectory at ``trajectory``, checked to have been recorded in ``world`` (the house at ``house``)."""
    from adaptenv.cli._common import check_recorded_in, existing_file
    from adaptenv.sim.trajectory import Trajectory

    traj = Trajectory.load(existing_file(trajectory, "trajectory file"))
    check_recorded_in(traj, world, trajectory, house)
    return traj


def analyze(
    house: Path = HOUSE_ARGUMENT,
    trajectory: Path = TRAJ_ARGUMENT,
    as_json: bool = typer.Option(False, "--json", help="Print the analysis as JSON."),
    llm: bool = typer.Option(False, "--llm", help="Ask an LLM (vision) instead of the built-in analyzer."),
    model: str | None = MODEL_OPTION,
    base_url: str | None = BASE_URL_OPTION,
    api: str | None = API_OPTION,
    api_key_env: str | None = KEY_ENV_OPTION,
    llm_cache: Path | None = CACHE_OPTION,
    prompts: str | None = PROMPTS_OPTION,
    llm_config_file: Path | None = LLM_CONFIG_OPTION,
) -> None:
    """Analyze one recorded episode (the paper's F): outcome, concerns and suggestions."""
    from adaptenv.adapt.analysis import BuiltinAnalyzer, LLMAnalyzer
    from adaptenv.sim.world import compile_world

    check_llm_config(llm_config_file)
    name, h = load_house_argument(house)
    world = compile_world(h, name)
    traj = load_trajectory_in(trajectory, world, house)
    analyzer = (LLMAnalyzer(llm_backend(model, base_url, llm_cache, "--llm", api=api, api_key_env=api_key_env,
                                        prompts=prompts, config_file=llm_config_file))
                if llm else BuiltinAnalyzer())
    result = analyzer.analyze(traj, world)
    typer.echo(result.model_dump_json(indent=1) if as_json else result.to_text())


def adapt(
    house: Path = ADAPT_HOUSE_ARGUMENT,
    out: Path = OUT_OPTION,
    policy: str = typer.Option("pretrained", "--policy", help="The agent G adapts the house to: pretrained (the "
                               "strongest shipped agent), pretrained-map, pretrained-scan, expert (shortest path, by "
                               "name only), explorer, map-explorer, random, a checkpoint (.pt), or module:attribute."),
    steps: int = typer.Option(5, "--steps", min=1, max=50, help="Single-object edits to make."),
    generator: str = typer.Option("builtin", "--generator", help="builtin (offline), failure-modes (offline, aims at "
                                  "F's failure families), learned (offline, a trained scorer ranks edits), llm, or random."),
    door_edits: bool = typer.Option(False, "--door-edits", help="With --generator failure-modes or llm: G may also "
                                    "open or shut interior doors."),
    relocate_targets: bool = typer.Option(False, "--relocate-targets", help="With --generator failure-modes: G may "
                                          "also move a target inside its room or to a far room where its type "
                                          "plausibly stands; otherwise no built-in edit moves a target."),
    learned_checks: int = typer.Option(0, "--learned-checks", min=0, max=64, help="With --generator learned: roll "
                                       "--policy out on this many of the best-scored edits each step and make the "
                                       "hardest for it (0: no rollout, the best-scored edit is made)."),
    learned_scorer: Path | None = typer.Option(None, "--learned-scorer", metavar="FILE.pt", help="With --generator "
                                               "learned: the scorer that ranks edits (adaptenv gdata train -o "
                                               "FILE.pt); default: the shipped one."),
    analyzer: str = typer.Option("builtin", "--analyzer", help="builtin (offline) or llm."),
    model: str | None = MODEL_OPTION,
    base_url: str | None = BASE_URL_OPTION,
    api: str | None = API_OPTION,
    api_key_env: str | None = KEY_ENV_OPTION,
    llm_cache: Path | None = CACHE_OPTION,
    prompts: str | None = PROMPTS_OPTION,
    price_in: float | None = PRICE_IN_OPTION,
    price_out: float | None = PRICE_OUT_OPTION,
    max_tokens: int | None = MAX_TOKENS_OPTION,
    max_cost: float | None = MAX_COST_OPTION,
    allow_target_moves: bool = TARGET_MOVES_OPTION,
    llm_config_file: Path | None = LLM_CONFIG_OPTION,
    seed: int = typer.Option(0, "--seed", callback=numbers.seed, help="Seed of the episode draw and the generator."),
    target: str | None = typer.Option(None, "--target", metavar="TYPE", help="Target object type (e.g. Fridge)."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON."),
    diagnose: int = typer.Option(0, "--diagnose", min=0, max=50, help="Diagnose this many hard episodes (F over "
                                 "several episodes; G aims at their failure modes; --target is then ignored)."),
    strict: bool = typer.Option(False, "--strict", help="With a folder: fail on the first house that cannot be "
                                "used instead of skipping it with a warning."),
    trajectory: Path | None = typer.Option(None, "--trajectory", metavar="TRAJ.json", help="An episode recorded in "
                                           "HOUSE (adaptenv rollout -o, adaptenv trajectory from-ai2thor) for F to "
                                           "analyze instead of rolling out --policy, which still checks G's edits "
                                           "and runs the episode again in the edited house."),
    target_success: float | None = typer.Option(None, "--target-success", metavar="P",
                                                  callback=numbers.finite, help="Difficulty on "
                                                  "request: edit until the policy's success on --target-episodes "
                                                  "fixed episodes is within --target-tolerance of P (0 < P < 1), "
                                                  "keeping only edits that bring it closer; --steps is the edit "
                                                  "budget."),
    target_tolerance: float = typer.Option(0.10, "--target-tolerance", callback=numbers.finite,
                                           help="With --target-success: stop when "
                                           "|success - P| is at most this."),
    target_episodes: int = typer.Option(20, "--target-episodes", min=1, max=500, help="With --target-success: "
                                        "episodes the success is measured on (the same after every edit)."),
    target_choices: int = TARGET_CHOICES_OPTION,
    target_draws: int = TARGET_DRAWS_OPTION,
    target_stop_gap: float | None = TARGET_STOP_GAP_OPTION,
    force: bool = FORCE_OPTION,
) -> None:
    """One closed-loop step: roll out the policy, analyze (F), edit the house (G), validate, write OUT.

    HOUSE may be a folder or a dataset (FILE.jsonl.gz[:START:STOP]): each usable house is adapted
    into OUT/NAME/ and OUT/summary.json counts the adapted, valid and skipped houses (exit 0 when
    at least one valid house was made). With --target-success P the edits aim at the policy's
    success rate P instead of the most difficulty (docs/adapt.md, "Difficulty on request").
    """
    from rich.console import Console

    from adaptenv.adapt.analysis import BuiltinAnalyzer, LLMAnalyzer
    from adaptenv.adapt.generators import GENERATORS, make_generator
    from adaptenv.agents.houses import SkippedHouse
    from adaptenv.agents.network import configure_torch
    from adaptenv.agents.registry import resolve_policy

    if generator not in GENERATORS:
        raise ConfigError(f"--generator {generator!r}: unknown generator; use one of {', '.join(GENERATORS)}")
    if door_edits and generator not in ("failure-modes", "llm"):
        raise ConfigError(f"--door-edits: only the failure-modes and llm generators edit doors; add --generator "
                          f"failure-modes or drop --door-edits (got --generator {generator})")
    if relocate_targets and generator != "failure-modes":
        raise ConfigError(f"--relocate-targets: only the failure-modes generator relocates targets; add --generator "
                          f"failure-modes or drop --relocate-targets (got --generator {generator})")
    if learned_checks and generator != "learned":
        raise ConfigError(f"--learned-checks: only the learned generator checks its edits this way; add --generator "
                          f"learned or drop --learned-checks (got --generator {generator})")
    if learned_scorer is not None and generator != "learned":
        raise ConfigError(f"--learned-scorer: only the learned generator reads a scorer; add --generator learned or "
                          f"drop --learned-scorer (got --generator {generator})")
    scorer = None
    if learned_scorer is not None:
        from adaptenv.adapt.generators.learned import load_scorer

        scorer = load_scorer(learned_scorer)  # a missing or foreign file is refused before any work
    if analyzer not in ("builtin", "llm"):
        raise ConfigError(f"--analyzer {analyzer!r}: unknown analyzer; use builtin or llm")
    check_llm_config(llm_config_file)
    if target_success is not None:
        from adaptenv.adapt.target import check_stop_gap, check_target

        check_target(target_success, target_tolerance)
        check_stop_gap(target_stop_gap, target_tolerance)
        if trajectory is not None or diagnose:
            raise ConfigError("--target-success: drop --trajectory and --diagnose (the success is measured on "
                              "--target-episodes episodes of the policy itself)")
    folder = output_folder(out, "-o", "adapt", force=force, inputs=[house, trajectory, policy, learned_scorer])
    many = _is_house_set(house, one=trajectory is not None)
    if trajectory is not None and (many or diagnose):
        raise ConfigError("--trajectory: give one house (a file or a one-line dataset slice FILE.jsonl.gz:2:3) and "
                          "no --diagnose (the trajectory is the episode F analyzes)")
    names, houses, skipped = _adapt_inputs(house, many, strict)
    before = None
    if trajectory is not None:
        from adaptenv.sim.world import compile_world

        before = load_trajectory_in(trajectory, compile_world(houses[0], names[0]), house)
        if target is not None and target != before.target_type:
            raise ConfigError(f"--target {target}: the trajectory looks for {before.target_type}; drop --target")
    configure_torch()  # one torch thread: G's rollout checks are many tiny batches
    console = Console()
    backend = None
    if "llm" in (generator, analyzer):
        backend = llm_backend(model, base_url, llm_cache, f"--{'generator' if generator == 'llm' else 'analyzer'} llm",
                              api=api, api_key_env=api_key_env, prompts=prompts, price_in=price_in,
                              price_out=price_out, max_tokens=max_tokens, max_cost=max_cost,
                              allow_target_moves=allow_target_moves, config_file=llm_config_file)
        if not as_json:
            d = backend.describe()
            console.print(f"LLM: {d['model']} at {d['base_url']} ({d['api']} API, prompts {d['prompts']})",
                          highlight=False)
    options = {"door_edits": True} if door_edits else {"checks": learned_checks} if learned_checks else {}
    options |= {"relocate_targets": True} if relocate_targets else {}
    options |= {"scorer": scorer} if scorer is not None else {}
    gen = (make_generator(generator, backend=backend, **options) if generator == "llm"
           else make_generator(generator, **options))
    if generator == "llm" and not as_json:
        gen.progress = lambda text: console.print(f"[dim]{text}[/]", highlight=False)
    f = LLMAnalyzer(backend) if analyzer == "llm" else BuiltinAnalyzer()
    pol = resolve_policy(policy, seed=seed)
    summaries = []
    with folder:
        for name, h in zip(names, houses, strict=True):
            where = out / name if many else out
            try:
                if target_success is not None:
                    s = _target_one(h, name, where, pol, f, gen, steps=steps, seed=seed, target=target,
                                    success=target_success, tolerance=target_tolerance, episodes=target_episodes,
                                    choices=target_choices, draws=target_draws, stop_gap=target_stop_gap)
                else:
                    s = _adapt_one(h, name, where, pol, f, gen, steps=steps, seed=seed, target=target,
                                   diagnose=diagnose, before=before)
            except AdaptenvError as exc:
                if not many or strict or isinstance(exc, PolicyError):  # a broken policy breaks every house
                    raise
                log.warning("skipping house %s: %s", name, exc)
                skipped.append(SkippedHouse(name, str(exc)))
                continue
            summaries.append(s)
            if as_json and not many:
                typer.echo(json.dumps(s, indent=1, default=str))
            elif not as_json and target_success is not None:
                _print_target_summary(console, s, where)
            elif not as_json:
                _print_adapt_summary(console, s, h, where)
        if many:
            _finish_folder(house, out, summaries, skipped, as_json)
    if not many and not summaries[0]["valid"]:
        raise typer.Exit(1)


def _adapt_one(h, name: str, out: Path, policy, analyzer, generator, *, steps: int, seed: int, target: str | None,
               diagnose: int, before: Trajectory | None = None) -> dict:
    """Adapt one house into ``out`` with :func:`~adaptenv.adapt.step.adapt_scene`; returns its summary.

    With ``before`` (an episode recorded in this house) F analyzes it instead of a rollout of ``policy``.
    """
    from adaptenv.adapt.diagnosis import hard_episodes
    from adaptenv.adapt.step import adapt_scene, result_edits_line, summarize, write_outputs
    from adaptenv.adapt.target import EPISODE_FRESH_DRAWS, fresh_measurement
    from adaptenv.agents.rollout import draw_episode
    from adaptenv.progress import ProgressBar
    from adaptenv.sim.task import Episode
    from adaptenv.sim.world import compile_world

    world = compile_world(h, name)
    if before is not None:
        episode = Episode(before.target_type, (before.start.x, before.start.z, before.start.yaw), before.seed)
    else:
        episode = draw_episode(world, np.random.default_rng([seed, 1]), target)
    episodes = hard_episodes(world, np.random.default_rng([seed, 2]), diagnose) if diagnose else None
    with ProgressBar(f"adapting {name}: rollout, F, G ({steps} edits), validation, rollout again"):
        result = adapt_scene(h, episode, policy=policy, analyzer=analyzer, generator=generator, steps=steps,
                             rng=np.random.default_rng(seed), name=name, render=True, render_dir=out / "steps",
                             episodes=episodes, before=before)
    s = summarize(result, analyzer=analyzer, seed=seed)
    s["edits_line"] = result_edits_line(result, steps)
    if result.valid and result.world is not None:  # G's own rollouts include the episode's draw; these do not
        fresh = [fresh_measurement(w, [episode], policy, EPISODE_FRESH_DRAWS) for w in (world, result.world)]
        s["fresh"] = {"draws": EPISODE_FRESH_DRAWS, "success_before": fresh[0].success,
                      "success_after": fresh[1].success}
    if before is not None:
        s["trajectory"] = {"policy": before.policy, "after_policy": result.after.policy}
    s |= _scorer_field(generator)
    write_outputs(result, s, out)
    return s


def _scorer_field(generator) -> dict:
    """``learned_scorer``, the scorer file that ranked the learned G's edits (nothing for other G)."""
    scorer = getattr(generator, "scorer", None)
    return {"learned_scorer": str(scorer.path)} if scorer is not None and scorer.path is not None else {}


def _target_one(h, name: str, out: Path, policy, analyzer, generator, *, steps: int, seed: int, target: str | None,
                success: float, tolerance: float, episodes: int, choices: int = 1, draws: int = 1,
                stop_gap: float | None = None) -> dict:
    """Edit one house toward the policy's success rate ``success`` with
    :func:`~adaptenv.adapt.target.adapt_to_success`; write it into ``out`` and return its summary."""
    from adaptenv.adapt.edits import edit_counts
    from adaptenv.adapt.objectives import realism_score
    from adaptenv.adapt.plausibility import audit
    from adaptenv.adapt.step import house_types
    from adaptenv.adapt.target import adapt_to_success
    from adaptenv.agents.policy import policy_name
    from adaptenv.progress import ProgressBar
    from adaptenv.render.compare import render_before_after
    from adaptenv.render.topdown import save_render
    from adaptenv.scene.house import save_house

    with ProgressBar(f"adapting {name} toward success {success:.2f}: measure, F, G, measure again ({steps} edits "
                     "at most)"):
        res = adapt_to_success(h, policy, generator, success, tolerance=tolerance, episodes=episodes, max_edits=steps,
                               analyzer=analyzer, seed=seed, target_type=target, name=name, choices=choices,
                               draws=draws, stop_gap=stop_gap)
    counts = edit_counts(res.edits, h, res.house)
    types = house_types(h)
    counts["objects"] = [{"type": types.get(o["id"]), **o} for o in counts["objects"]]
    doc = res.to_dict()
    summary = {"house": name, "policy": policy_name(policy), "analyzer": analyzer.name, "generator": doc["generator"],
               "seed": seed, "target_success": {k: v for k, v in doc.items() if k != "trace"},
               "episodes": [{"target_type": e.target_type, "start": list(e.start), "seed": e.seed} for e in res.episodes],
               "edits_applied": len(res.edits), "edit_counts": counts,
               "plausibility": audit(h, res.house).counts(), "realism_before": realism_score(h, h),
               "realism_after": realism_score(res.house, h), "env_steps": res.env_steps, "valid": True, "problems": [],
               **_scorer_field(generator)}
    out.mkdir(parents=True, exist_ok=True)
    save_house(res.house, out / "house.json")
    pair = render_before_after(h, res.house, res.trajectories_before[0], res.trajectories_after[0],
                               [o["id"] for o in counts["objects"] if o["changed"]])
    save_render(pair.side_by_side(), out / "before_after.png")
    atomic_write_text(out / "edits.json", json.dumps(res.generation_log(), indent=1, default=str))
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=1, default=str))
    return {**summary, "target_success": doc}


def _print_target_summary(console, s: dict, out: Path) -> None:
    """The human-readable summary of one house edited toward a success rate: target, reached, gap, edits."""
    t = s["target_success"]
    draws = f" x {t['draws']} action draws" if t.get("draws", 1) > 1 else ""
    console.print(f"policy {s['policy']}, analyzer {s['analyzer']}, generator {s['generator']}; success measured on "
                  f"{t['episodes']} fixed episodes{draws}; editing stops within {t['stop_gap']:.3g} of the target",
                  highlight=False, soft_wrap=True)
    console.print(f"target success {t['target']:.2f} +/- {t['tolerance']:.2f}: reached {t['success']:.2f} (from "
                  f"{t['success_before']:.2f}), gap {t['gap']:.2f}, {t['edits']} edit(s) kept of {t['proposed']} "
                  f"proposed; {t['stopped']}", highlight=False, soft_wrap=True)
    console.print("success after each kept edit: " + " -> ".join(f"{x:.2f}" for x in t["success_trace"]),
                  highlight=False, soft_wrap=True)
    if t.get("fresh_draws"):
        console.print(f"on {t['fresh_draws']} fresh action draws per episode (not selected on): success "
                      f"{t['fresh_success_before']:.2f} -> {t['fresh_success']:.2f}, gap {t['fresh_gap']:.2f}: "
                      f"{'within' if t['fresh_reached'] else 'not within'} the tolerance",
                      highlight=False, soft_wrap=True)
    if (hint := target_hint(t)) is not None:
        console.print(hint, highlight=False, soft_wrap=True)
    console.print(edit_counts_text(s["edit_counts"]), highlight=False, soft_wrap=True)
    bad = {k: v for k, v in s["plausibility"].items() if v}
    console.print("plausibility audit of the moved objects: " + (", ".join(f"{k} {v}" for k, v in bad.items())
                                                                 if bad else "no violation") +
                  f"; realism {_fmt(s['realism_before'])} -> {_fmt(s['realism_after'])}", highlight=False, soft_wrap=True)
    console.print(f"wrote {out}/ (house.json, before_after.png, edits.json, summary.json)", soft_wrap=True)


def target_hint(t: dict) -> str | None:
    """What to try when a run toward a success rate missed it (judged on the fresh draws when it made them), or None."""
    if (t["fresh_reached"] if t.get("fresh_draws") else t["reached"]):
        return None
    if t["reached"]:
        return ("P reached on the run's own draws but not on fresh ones: the measured success moves by an episode or "
                "two between draws of the agent's actions; more --target-episodes measure it more closely")
    if t["stopped"] == "edit budget used":
        return "P not reached: the edit budget (--steps) was used up; a larger --steps may come closer"
    if t["stopped"].startswith("no kept edit"):
        return ("P not reached: no edit G proposed came closer in the last rounds; a single-object edit moves a strong "
                "agent's success by a few points on average, so a distant P may lie out of reach of edits to this house "
                "(docs/results/target-success in the adaptenv repository measures how far each G gets)")
    return None


def _is_house_set(house: Path, one: bool = False) -> bool:
    """Whether HOUSE names several houses (a folder, or a dataset unless ``one`` house is asked for)."""
    from adaptenv.scene.dataset import parse_dataset_spec

    return house.is_dir() or (not one and parse_dataset_spec(house) is not None)


def _adapt_inputs(house: Path, many: bool, strict: bool) -> tuple[list[str], list, list]:
    """(names, houses, skipped): one file (its errors stay errors) or a set (unusable houses skipped)."""
    from adaptenv.agents.houses import load_house_set

    if many:
        hs = load_house_set(house, strict=strict)
        return hs.names, hs.houses, list(hs.skipped)
    name, h = load_house_argument(house)
    return [name], [h], []


def _finish_folder(house: Path, out: Path, summaries: list[dict], skipped: list, as_json: bool) -> None:
    """Summary of a folder run; exit 1 unless at least one house was adapted into a valid house."""
    valid = sum(bool(s["valid"]) for s in summaries)
    doc = {"houses": str(house), "adapted": len(summaries), "valid": valid, "skipped": len(skipped),
           "skipped_houses": {h.name: h.reason for h in skipped}}
    atomic_write_text(out / "summary.json", json.dumps(doc, indent=1) + "\n")
    if as_json:
        typer.echo(json.dumps({**doc, "summaries": summaries}, indent=1, default=str))
    else:
        typer.echo(f"{house}: adapted {len(summaries)} house(s) ({valid} valid), skipped {len(skipped)}; "
                   f"wrote {out}/summary.json")
    if valid == 0:
        raise typer.Exit(1)


def _print_adapt_summary(console, s: dict, h, out: Path) -> None:
    """The human-readable summary of one adapted house (units stated; which way is harder)."""
    from adaptenv.adapt.diagnosis import SceneDiagnosis
    from adaptenv.adapt.objectives import MEANING, harder_or_easier
    from adaptenv.scene.grid import NormalizedGrid

    ob, oa = s["objective_before"], s["objective_after"]
    ab, aa = s["agent_before"], s["agent_after"]
    ep = s["episode"]
    gx, gy = NormalizedGrid.for_house(h).point(ep["start"][0], ep["start"][1])
    console.print(f"episode: find a {ep['target_type']} from ({ep['start'][0]:.2f}, {ep['start'][1]:.2f}) m, "
                  f"grid ({gx:.0f}, {gy:.0f}) of 0..100; policy {s['policy']}, analyzer {s['analyzer']}, "
                  f"generator {s['generator']}")
    console.print(f"edits applied: {s['edits_applied']} of {s['steps_requested']} "
                  f"({s['edits_verified']} verified); moves are in grid units (0..100 across the house)")
    console.print(s["edits_line"], highlight=False, soft_wrap=True)
    console.print(edit_counts_text(s["edit_counts"]), highlight=False)
    console.print("objectives along the episode's route (before -> after):")
    for k in ob:
        what, unit = MEANING.get(k, (k, ""))
        console.print(f"  {k:15s} {_fmt(ob[k])} -> {_fmt(oa[k])} {unit:8s} {what}: "
                      f"{harder_or_easier(k, ob[k], oa[k])}")
    console.print(f"agent: success {ab['success']} -> {aa['success']}, SPL {ab['spl']:.3f} -> {aa['spl']:.3f}, "
                  f"steps {ab['steps']} -> {aa['steps']}: {_verdict_text(s['verdict'], ab, aa)}")
    if f := s.get("fresh"):
        console.print(f"  on {f['draws']} fresh action draws of the episode (no G rolled them out): success "
                      f"{f['success_before']:.2f} -> {f['success_after']:.2f}", highlight=False, soft_wrap=True)
    if t := s.get("trajectory"):
        console.print(f"  before: {t['policy']}'s recorded episode; after: {t['after_policy']} in the edited house "
                      "(a different agent: compare with care)", highlight=False)
    if s.get("diagnosis"):
        before, after = (SceneDiagnosis.model_validate(s[k]) for k in ("diagnosis", "diagnosis_after"))
        console.print(f"diagnosis before: {before.summary()}", highlight=False)
        console.print(f"diagnosis after:  {after.summary()}", highlight=False)
    bad = {k: v for k, v in s["plausibility"].items() if v}
    console.print("plausibility audit of the moved objects: " + (", ".join(f"{k} {v}" for k, v in bad.items())
                                                                 if bad else "no violation"), highlight=False)
    console.print(f"realism: {_fmt(s['realism_before'])} -> {_fmt(s['realism_after'])}; expert solvable: "
                  f"{s['expert_solvable']}, expert success: {s['expert_success_after']}; valid: {s['valid']}")
    for p in s["problems"]:
        console.print(f"  [red]problem:[/] {p}", highlight=False)
    if s.get("stopped"):
        console.print(f"[yellow]G stopped early:[/] {s['stopped']}", highlight=False)
    if s.get("llm"):
        for role, u in s["usage"]["by_role"].items():
            console.print(f"tokens {role:6s} {_usage_text(u)}", highlight=False)
        console.print(f"tokens total  {_usage_text(s['usage'])}", highlight=False)
    console.print(f"wrote {out}/ (house.json, before.png, after.png, analysis.json, edits.json, summary.json)")


def edit_counts_text(c: dict) -> str:
    """The edit counts in words: distinct objects (type beside id, edits each) and what changed on net."""
    from adaptenv.scene.assets import object_label

    if not c["edits"]:
        return "no edit applied"
    objects = ", ".join(f"{object_label(o['id'], o['type'])} x{o['edits']}"
                        + ("" if o["changed"] else " (back where it stood)") for o in c["objects"])
    return (f"{c['edits']} edit{'s' if c['edits'] != 1 else ''} of {c['objects_edited']} object"
            f"{'s' if c['objects_edited'] != 1 else ''} ({objects}); {c['objects_changed']} changed on net, "
            f"net displacement {c['net_displacement_m']:.2f} m")


def _verdict_text(v: str, before: dict, after: dict) -> str:
    """The closing words of the agent line: :func:`~adaptenv.adapt.step.verdict` and what decided it."""
    if v == "unchanged":
        return "unchanged for the agent (same success, same SPL)"
    why = "success" if bool(before["success"]) != bool(after["success"]) else "SPL at equal success"
    return f"the scene got {v} for the agent ({why} {'fell' if v == 'harder' else 'rose'})"


def _fmt(x) -> str:
    return "n/a" if x is None else f"{x:.3f}"


def _usage_text(u: dict) -> str:
    """One line of a usage dict: tokens in (cached) / out, calls, retries, cache hits, cost."""
    cost = f", ${u['cost_usd']:.4f}" if "cost_usd" in u else ""
    return (f"{u['input_tokens']:,} in ({u['cached_tokens']:,} cached) / {u['output_tokens']:,} out, "
            f"{u['calls']} calls, {u['retries']} retries, {u['cache_hits']} cache hits{cost}")


def bench_adapt(
    houses: int = typer.Option(50, "--houses", min=1, help="Procedural houses the policy solves."),
    steps: int = typer.Option(5, "--steps", min=1, help="Built-in edits per house."),
    policy: str = typer.Option("pretrained", "--policy", help="Policy to adapt to (pretrained, expert, ...)."),
    seed: int = typer.Option(0, "--seed", callback=numbers.seed, help="Seed of houses and episodes."),
    rooms: int = typer.Option(5, "--rooms", min=1, help="Rooms per procedural house."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Adapt many solved houses with the built-in G: agent drop, expert success, realism vs random, speed."""
    from adaptenv.bench import emit
    from adaptenv.bench.adapt import NOTES, run

    figures = run(houses=houses, steps=steps, policy=policy, seed=seed, rooms=rooms)
    emit("adapt: built-in G on solved procedural houses", figures, as_json, notes=NOTES)


def audit(
    original: Path = typer.Argument(..., metavar="ORIGINAL", show_default=False,
                                    help="The house before editing: a house JSON file or one line of a dataset, "
                                         "e.g. FILE.jsonl.gz:2:3."),
    adapted: Path = typer.Argument(..., metavar="ADAPTED.json", show_default=False,
                                   help="The same house after editing (e.g. OUT/house.json of `adaptenv adapt`)."),
    reference: Path | None = typer.Option(None, "--reference", metavar="FILE",
                                          help="Placement reference of the unlike_reference rule: houses to learn "
                                               "from (FILE.jsonl.gz, one house a line) or a reference JSON "
                                               "(tools/build_placement_reference.py); default: the shipped one, "
                                               "learned from procedural houses."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Plausibility audit: every moved object checked against the original (docs/adapt.md); exit 1 on a violation."""
    from adaptenv.adapt.placement_model import load_model
    from adaptenv.adapt.plausibility import audit as run_audit
    from adaptenv.adapt.step import house_types
    from adaptenv.scene.assets import object_label

    model = load_model(reference) if reference is not None else None
    _, before = load_house_argument(original, "original house")
    _, after = load_house_argument(adapted, "adapted house")
    report = run_audit(before, after, model=model)
    types = house_types(before, after)
    if as_json:
        typer.echo(json.dumps({"moved": report.moved, "moved_types": [types.get(o) for o in report.moved],
                               "counts": report.counts(),
                               "violations": [{"rule": v.rule, "object": v.object_id,
                                               "object_type": types.get(v.object_id), "others": list(v.others),
                                               "other_types": [types.get(o) for o in v.others],
                                               "feature": v.feature or None, "message": v.message} for v in report.violations]}, indent=1))
    else:
        for v in report.violations:
            unnamed = [o for o in dict.fromkeys((v.object_id, *v.others))
                       if object_label(o, types.get(o)) != o and f"{o} ({types[o]})" not in str(v)]
            typer.echo(str(v) + (f" ({', '.join(f'{o} is a {types[o]}' for o in unnamed)})" if unnamed else ""))
        counts = ", ".join(f"{k} {n}" for k, n in report.counts().items())
        typer.echo(f"{len(report.moved)} moved object(s), {report.total} violation(s): {counts}")
    if report.total:
        raise typer.Exit(1)


def bench_plausibility(
    houses: int = typer.Option(50, "--houses", min=1, help="Procedural houses to adapt."),
    steps: int = typer.Option(5, "--steps", min=1, help="Edits per house and generator."),
    seed: int = typer.Option(0, "--seed", callback=numbers.seed, help="Seed of houses, episodes and edits."),
    rooms: int = typer.Option(5, "--rooms", min=1, help="Rooms per procedural house."),
    real: Path | None = typer.Option(None, "--real", metavar="HOUSE.json",
                                     help="Also adapt this house (e.g. a real ProcTHOR house) 5 times."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Plausibility audit of G's houses beside random perturbation: violations per rule."""
    from adaptenv.bench import emit
    from adaptenv.bench.plausibility import NOTES, run
    from adaptenv.cli._common import existing_file

    figures = run(houses=houses, steps=steps, seed=seed, rooms=rooms,
                  real=existing_file(real, "--real house") if real is not None else None)
    emit("plausibility: violations of G's edits and of random perturbation", figures, as_json, notes=NOTES)


def register(app: typer.Typer, bench: typer.Typer) -> None:
    app.command("analyze")(analyze)
    app.command("adapt")(adapt)
    app.command("audit")(audit)
    bench.command("adapt")(bench_adapt)
    bench.command("plausibility")(bench_plausibility)
