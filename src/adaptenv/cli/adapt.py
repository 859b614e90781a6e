"""``adaptenv analyze`` (F on a recorded episode), ``adaptenv adapt`` (one closed-loop step) and ``adaptenv bench adapt``."""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

import typer

from adaptenv.agents.houses import SkippedHouse
from adaptenv.cli._common import JSON_OPTION
from adaptenv.errors import AdaptenvError

log = logging.getLogger(__name__)

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


ADAPT_HOUSE_ARGUMENT = typer.Argument(..., metavar="HOUSE", show_default=False,
                                      help="House JSON file (ProcTHOR format), or a folder of them (each adapted "
                                           "into OUT/NAME/; houses that cannot be used are skipped).")


def adapt(
    house: Path = ADAPT_HOUSE_ARGUMENT,
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
    strict: bool = typer.Option(False, "--strict", help="With a folder: fail on the first house that cannot be "
                                "used instead of skipping it with a warning."),
) -> None:
    """One closed-loop step: roll out the policy, analyze (F), edit the house (G), validate, write OUT."""
    from adaptenv.adapt.analysis import BuiltinAnalyzer, LLMAnalyzer
    from adaptenv.adapt.generators import GENERATORS, make_generator
    from adaptenv.adapt.pipeline import adapt_house, resolve_policy_spec
    from adaptenv.errors import ConfigError

    if generator not in GENERATORS:
        raise ConfigError(f"--generator {generator!r}: unknown generator; use one of {', '.join(GENERATORS)}")
    if analyzer not in ("builtin", "llm"):
        raise ConfigError(f"--analyzer {analyzer!r}: unknown analyzer; use builtin or llm")
    names, houses, skipped = _adapt_inputs(house, strict)
    backend = None
    if "llm" in (generator, analyzer):
        backend = llm_backend(model, base_url, llm_cache, f"--{'generator' if generator == 'llm' else 'analyzer'} llm")
    gen = make_generator(generator, backend=backend) if generator == "llm" else make_generator(generator)
    f = LLMAnalyzer(backend) if analyzer == "llm" else BuiltinAnalyzer()
    pol = resolve_policy_spec(policy, seed=seed)
    summaries = []
    for name, h in zip(names, houses, strict=True):
        folder = out / name if house.is_dir() else out
        try:
            result = adapt_house(h, policy=pol, analyzer=f, generator=gen, steps=steps, seed=seed,
                                 target_type=target, out_dir=folder, name=name)
        except AdaptenvError as exc:
            if not house.is_dir() or strict:
                raise
            log.warning("skipping house %s: %s", name, exc)
            skipped.append(SkippedHouse(name, str(exc)))
            continue
        summaries.append(result.summary)
        if as_json and not house.is_dir():
            typer.echo(json.dumps(result.summary, indent=1, default=str))
        elif not as_json:
            _print_adapt_summary(result.summary, folder)
    if house.is_dir():
        _finish_folder(house, out, summaries, skipped, as_json)
    elif not summaries[0]["valid"]:
        raise typer.Exit(1)


def _adapt_inputs(house: Path, strict: bool) -> tuple[list[str], list, list[SkippedHouse]]:
    """(names, houses, skipped): one file (its errors stay errors) or a folder (unusable houses skipped)."""
    from adaptenv.agents.houses import load_house_set
    from adaptenv.cli._common import existing_file
    from adaptenv.scene.house import load_house

    if house.is_dir():
        hs = load_house_set(house, strict=strict)
        return hs.names, hs.houses, list(hs.skipped)
    return [house.stem], [load_house(existing_file(house, "house file"))], []


def _finish_folder(house: Path, out: Path, summaries: list[dict], skipped: list, as_json: bool) -> None:
    """Summary of a folder run; exit 1 unless at least one house was adapted into a valid house."""
    valid = sum(bool(s["valid"]) for s in summaries)
    doc = {"houses": str(house), "adapted": len(summaries), "valid": valid, "skipped": len(skipped),
           "skipped_houses": {h.name: h.reason for h in skipped}}
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    if as_json:
        typer.echo(json.dumps({**doc, "summaries": summaries}, indent=1, default=str))
    else:
        typer.echo(f"{house}: adapted {len(summaries)} house(s) ({valid} valid), skipped {len(skipped)}; "
                   f"wrote {out}/summary.json")
    if valid == 0:
        raise typer.Exit(1)


def _print_adapt_summary(s: dict, out: Path) -> None:
    """The human-readable summary of one adapted house."""
    from rich.console import Console

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
    console.print(f"realism: {_fmt(s['realism_before'])} -> {_fmt(s['realism_after'])}; expert solvable: "
                  f"{s['expert_solvable']}, expert success: {s['expert_success_after']}; valid: {s['valid']}")
    for p in s["problems"]:
        console.print(f"  [red]problem:[/] {p}", highlight=False)
    if s.get("usage"):
        console.print(f"tokens: {s['usage']}")
    console.print(f"wrote {out}/ (house.json, before.png, after.png, analysis.json, edits.json, summary.json)")


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
