"""``adaptenv analyze`` (F on a recorded episode), ``adaptenv adapt`` (one closed-loop step) and ``adaptenv bench adapt``."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import typer

from adaptenv.cli._common import JSON_OPTION

HOUSE_ARGUMENT = typer.Argument(..., metavar="HOUSE.json", help="House JSON file (ProcTHOR format).",
                                show_default=False)
TRAJ_ARGUMENT = typer.Argument(..., metavar="TRAJ.json", help="Trajectory JSON (from `adaptenv rollout -o`).",
                               show_default=False)
MODEL_OPTION = typer.Option("gpt-4.1-mini", "--model", help="LLM model name (the paper used gpt-4.1-mini).")
BASE_URL_OPTION = typer.Option(None, "--base-url", metavar="URL",
                               help="OpenAI-compatible server ending in /v1 (vLLM, Ollama, llama.cpp); "
                                    "without it the OpenAI API is used and OPENAI_API_KEY must be set.")
OUT_OPTION = typer.Option(..., "-o", "--out", help="Folder for the adapted house, renders and logs.")
CACHE_OPTION = typer.Option(None, "--llm-cache", metavar="DIR", help="Cache LLM answers in this folder.")


def llm_backend(model: str, base_url: str | None, cache_dir: Path | None, what: str):
    """An LLM backend for ``what`` (e.g. '--generator llm'); one-line errors when no server is configured."""
    from adaptenv.adapt.llm import LLMConfig, make_backend
    from adaptenv.errors import ConfigError

    if base_url is None and not os.environ.get("OPENAI_API_KEY"):
        raise ConfigError(f"{what} needs a model server: set OPENAI_API_KEY for the OpenAI API, or pass "
                          "--base-url http://localhost:11434/v1 (any OpenAI-compatible server)")
    provider = "openai" if base_url is None else "openai-compatible"
    return make_backend(LLMConfig(provider=provider, model=model, base_url=base_url, cache_dir=cache_dir))


def analyze(
    house: Path = HOUSE_ARGUMENT,
    trajectory: Path = TRAJ_ARGUMENT,
    as_json: bool = typer.Option(False, "--json", help="Print the analysis as JSON."),
    llm: bool = typer.Option(False, "--llm", help="Ask an LLM (vision) instead of the built-in analyzer."),
    model: str = MODEL_OPTION,
    base_url: str | None = BASE_URL_OPTION,
    llm_cache: Path | None = CACHE_OPTION,
) -> None:
    """Analyze one recorded episode (the paper's F): outcome, concerns and suggestions."""
    from adaptenv.adapt.analysis import BuiltinAnalyzer, LLMAnalyzer
    from adaptenv.cli._common import existing_file
    from adaptenv.scene.house import load_house
    from adaptenv.sim.trajectory import Trajectory
    from adaptenv.sim.world import compile_world

    h = load_house(existing_file(house, "house file"))
    traj = Trajectory.load(existing_file(trajectory, "trajectory file"))
    world = compile_world(h, house.stem)
    analyzer = LLMAnalyzer(llm_backend(model, base_url, llm_cache, "--llm")) if llm else BuiltinAnalyzer()
    result = analyzer.analyze(traj, world)
    typer.echo(result.model_dump_json(indent=1) if as_json else result.to_text())


def adapt(
    house: Path = HOUSE_ARGUMENT,
    out: Path = OUT_OPTION,
    policy: str = typer.Option("expert", "--policy", help="pretrained, expert, random, a checkpoint (.pt), "
                               "or module:attribute."),
    steps: int = typer.Option(5, "--steps", min=1, max=50, help="Single-object edits to make."),
    generator: str = typer.Option("builtin", "--generator", help="builtin (offline), llm, or random."),
    analyzer: str = typer.Option("builtin", "--analyzer", help="builtin (offline) or llm."),
    model: str = MODEL_OPTION,
    base_url: str | None = BASE_URL_OPTION,
    llm_cache: Path | None = CACHE_OPTION,
    seed: int = typer.Option(0, "--seed", help="Seed of the episode draw and the generator."),
    target: str | None = typer.Option(None, "--target", metavar="TYPE", help="Target object type (e.g. Fridge)."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON."),
    diagnose: int = typer.Option(0, "--diagnose", min=0, max=50, help="Diagnose this many hard episodes (F over "
                                 "several episodes; G aims at their failure modes; --target is then ignored)."),
) -> None:
    """One closed-loop step: roll out the policy, analyze (F), edit the house (G), validate, write OUT."""
    from rich.console import Console

    from adaptenv.adapt.analysis import BuiltinAnalyzer, LLMAnalyzer
    from adaptenv.adapt.diagnosis import hard_episodes
    from adaptenv.adapt.generators import GENERATORS, make_generator
    from adaptenv.adapt.step import adapt_scene, summarize, write_outputs
    from adaptenv.agents.registry import resolve_policy
    from adaptenv.agents.rollout import draw_episode
    from adaptenv.cli._common import existing_file
    from adaptenv.errors import ConfigError
    from adaptenv.scene.house import load_house
    from adaptenv.sim.world import compile_world

    if generator not in GENERATORS:
        raise ConfigError(f"--generator {generator!r}: unknown generator; use one of {', '.join(GENERATORS)}")
    if analyzer not in ("builtin", "llm"):
        raise ConfigError(f"--analyzer {analyzer!r}: unknown analyzer; use builtin or llm")
    h = load_house(existing_file(house, "house file"))
    backend = None
    if "llm" in (generator, analyzer):
        backend = llm_backend(model, base_url, llm_cache, f"--{'generator' if generator == 'llm' else 'analyzer'} llm")
    gen = make_generator(generator, backend=backend) if generator == "llm" else make_generator(generator)
    f = LLMAnalyzer(backend) if analyzer == "llm" else BuiltinAnalyzer()
    world = compile_world(h, house.stem)
    episode = draw_episode(world, np.random.default_rng([seed, 1]), target)
    episodes = hard_episodes(world, np.random.default_rng([seed, 2]), diagnose) if diagnose else None
    result = adapt_scene(h, episode, policy=resolve_policy(policy, seed=seed), analyzer=f, generator=gen, steps=steps,
                         rng=np.random.default_rng(seed), name=house.stem, render=True, render_dir=out / "steps",
                         episodes=episodes)
    s = summarize(result, analyzer=f.name, seed=seed)
    write_outputs(result, s, out)
    if as_json:
        typer.echo(json.dumps(s, indent=1, default=str))
    else:
        console = Console()
        ob, oa = s["objective_before"], s["objective_after"]
        ab, aa = s["agent_before"], s["agent_after"]
        ep = s["episode"]
        console.print(f"episode: find a {ep['target_type']} from ({ep['start'][0]:.2f}, {ep['start'][1]:.2f}); "
                      f"policy {s['policy']}, analyzer {s['analyzer']}, generator {s['generator']}")
        console.print(f"edits applied: {s['edits_applied']} of {s['steps_requested']} "
                      f"({s['edits_verified']} verified)")
        for k in ob:
            console.print(f"  {k:15s} {_fmt(ob[k])} -> {_fmt(oa[k])}")
        console.print(f"agent: success {ab['success']} -> {aa['success']}, SPL {ab['spl']:.3f} -> {aa['spl']:.3f}")
        if result.diagnosis is not None:
            console.print(f"diagnosis before: {result.diagnosis.summary()}", highlight=False)
            console.print(f"diagnosis after:  {result.diagnosis_after.summary()}", highlight=False)
        console.print(f"realism: {_fmt(s['realism_before'])} -> {_fmt(s['realism_after'])}; expert solvable: "
                      f"{s['expert_solvable']}, expert success: {s['expert_success_after']}; valid: {s['valid']}")
        for p in s["problems"]:
            console.print(f"  [red]problem:[/] {p}", highlight=False)
        if s.get("usage"):
            console.print(f"tokens: {s['usage']}")
        console.print(f"wrote {out}/ (house.json, before.png, after.png, analysis.json, edits.json, summary.json)")
    if not s["valid"]:
        raise typer.Exit(1)


def _fmt(x) -> str:
    return "n/a" if x is None else f"{x:.3f}"


def bench_adapt(
    houses: int = typer.Option(50, "--houses", min=1, help="Procedural houses the policy solves."),
    steps: int = typer.Option(5, "--steps", min=1, help="Built-in edits per house."),
    policy: str = typer.Option("pretrained", "--policy", help="Policy to adapt to (pretrained, expert, ...)."),
    seed: int = typer.Option(0, "--seed", help="Seed of houses and episodes."),
    rooms: int = typer.Option(5, "--rooms", min=1, help="Rooms per procedural house."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Adapt many solved houses with the built-in G: agent drop, expert success, realism vs random, speed."""
    from adaptenv.bench import emit
    from adaptenv.bench.adapt import NOTES, run

    figures = run(houses=houses, steps=steps, policy=policy, seed=seed, rooms=rooms)
    emit("adapt: built-in G on solved procedural houses", figures, as_json, notes=NOTES)


def register(app: typer.Typer, bench: typer.Typer) -> None:
    app.command("analyze")(analyze)
    app.command("adapt")(adapt)
    bench.command("adapt")(bench_adapt)
