"""``adaptenv gdata collect`` (candidate edits and their measured effect on an agent) and ``adaptenv gdata train``
(the learned G's scorer, trained on such data).

Commands import their dependencies when they run, so ``adaptenv --help`` stays fast and never loads torch.
"""

from __future__ import annotations

from pathlib import Path

import typer

from adaptenv.cli import _numbers as numbers
from adaptenv.cli._outputs import command_line, output_folder
from adaptenv.errors import ConfigError
from adaptenv.files import atomic_write_text

gdata_app = typer.Typer(help="Data for a learned G: collect candidate edits with their effect on an agent, train "
                             "the learned G on them.", no_args_is_help=True, rich_markup_mode=None)

HOUSES_OPTION = typer.Option(..., "--houses", metavar="SPEC", help="Training houses (repeatable): preset:NAME (e.g. "
                             "preset:pretrain-train), a folder of house files, a file, or a dataset "
                             "FILE.jsonl[.gz][:START:STOP]. Never a held-out suite.")


TRAINING_PRESETS = ("preset:pretrain-train", "preset:pretrain-rearranged")
"""The presets of the suites that are the agent's own training houses (the other suites' houses are held out)."""


def training_houses(spec: str) -> bool:
    """Whether ``spec`` may be collected from: not a suite, and no preset a held-out or validation suite uses."""
    from adaptenv.agents.suites import SUITES

    if spec.startswith("suite:"):
        return False
    return spec in TRAINING_PRESETS or spec not in {s.houses for s in SUITES.values()}


@gdata_app.command("collect")
def collect(
    houses: list[str] = HOUSES_OPTION,
    out: Path = typer.Option(..., "-o", "--out", help="Dataset folder (edits.jsonl.gz, houses.jsonl, meta.json); "
                             "running again with the same settings continues it."),
    policy: str = typer.Option("pretrained", "--policy", help="The agent whose success and SPL each edit is measured "
                               "on: pretrained, pretrained-map, pretrained-scan, expert, a checkpoint (.pt), ..."),
    tasks: int = typer.Option(2, "--tasks", min=1, max=20, help="Episodes per house that F analyses and G edits for."),
    candidates: int = typer.Option(24, "--candidates", min=2, max=256, help="Candidate edits per task (the built-in "
                                   "G's route moves and random moves, as --random-share splits them)."),
    random_share: float = typer.Option(0.5, "--random-share", min=0.0, max=1.0, help="Share of the candidates drawn "
                                       "as random moves (the rest the built-in G's route moves; the learned G "
                                       "draws route moves only)."),
    episodes: int = typer.Option(3, "--episodes", min=0, max=16, help="Paired episodes (the task's start and target, "
                                 "headings spread evenly) each accepted edit is measured on, before and after (0: "
                                 "only the route objectives, for `gdata train --target objectives`)."),
    seed: int = typer.Option(0, "--seed", callback=numbers.seed, help="Seed of the episode and candidate draws."),
    limit: int = typer.Option(0, "--limit", min=0, help="Use only the first N houses of each --houses (0: all)."),
) -> None:
    """Run the built-in and random G's candidate edits over many houses and record each one's placement, validation,
    plausibility audit and measured effect on the agent (one row per candidate in OUT/edits.jsonl.gz)."""
    from rich.console import Console

    from adaptenv.adapt.gdata import CollectConfig, collect, house_sha256
    from adaptenv.agents.houses import load_house_set
    from adaptenv.agents.network import configure_torch
    from adaptenv.agents.registry import resolve_policy
    from adaptenv.progress import ProgressBar

    if bad := next((h for h in houses if not training_houses(h)), None):
        raise ConfigError(f"--houses {bad}: the houses of a held-out or validation suite are not training data; "
                          "pass training houses such as preset:pretrain-train")
    folder = output_folder(out, "-o", "gdata collect", inputs=[*houses, policy], keep=True, force_flag=None)
    configure_torch()
    pol = resolve_policy(policy, seed=seed)
    pairs = []
    for spec in houses:
        hs = load_house_set(spec)
        n = len(hs.houses) if limit == 0 else min(limit, len(hs.houses))
        pairs += [(h, {"spec": spec, "name": w.name, "index": i, "sha256": house_sha256(h)})
                  for i, (h, w) in enumerate(zip(hs.houses[:n], hs.worlds[:n], strict=True))]
    cfg = CollectConfig(tasks=tasks, candidates=candidates, episodes=episodes, seed=seed, random_share=random_share)
    console = Console()
    with folder, ProgressBar("collecting edits", len(pairs)) as bar:
        counts = collect(pairs, pol, cfg, out, progress=lambda key: bar.advance(), command=command_line())
    measured = (f"{counts['measured']} measured on {policy}" if episodes else
                "the route objectives of those the expert still solves, no agent rollout")
    console.print(f"{counts['houses']} houses, {counts['rows']} candidate edits ({counts['accepted']} accepted by "
                  f"placement and validation, {measured}); wrote {out / 'edits.jsonl.gz'}", highlight=False)


@gdata_app.command("train")
def train(
    data: list[Path] = typer.Argument(..., metavar="DATA", show_default=False,
                                      help="Collection folders written by `adaptenv gdata collect -o`."),
    out: Path = typer.Option(..., "-o", "--out", help="The scorer checkpoint to write (FILE.pt); its card is written "
                             "beside it as FILE.json."),
    epochs: int = typer.Option(60, "--epochs", min=1, max=10_000, help="Passes over the training houses' rows."),
    seed: int = typer.Option(0, "--seed", callback=numbers.seed, help="Seed of the initial weights and batches."),
    hidden: int = typer.Option(64, "--hidden", min=1, max=1024, help="Hidden width of the MLP."),
    layers: int = typer.Option(2, "--layers", min=0, max=8, help="Hidden layers of the MLP."),
    lr: float = typer.Option(3e-3, "--lr", min=1e-6, max=1.0, callback=numbers.finite, help="AdamW learning rate."),
    heldin: int = typer.Option(5, "--heldin", min=2, max=100, help="Hold in one house in this many (by a hash of "
                               "its name) to choose the epoch on; those houses are never trained on."),
    target: str = typer.Option("agent", "--target", help="What the scorer predicts beside acceptance: the agent's measured drops in success "
                               "and SPL (agent), or the gain of each of the built-in G's route objectives, measured "
                               "without rollouts (objectives)."),
    force: bool = typer.Option(False, "--force", help="Replace an output file adaptenv did not write."),
) -> None:
    """Train the learned G's scorer (an MLP over each candidate edit's features) and keep the epoch that ranks edits
    best on the held-in houses; writes OUT and its card OUT.json."""
    import json

    from rich.console import Console

    from adaptenv.adapt.gtrain import TrainConfig
    from adaptenv.adapt.gtrain import train as run_train
    from adaptenv.agents.network import configure_torch
    from adaptenv.cli._outputs import output_file, recording
    from adaptenv.progress import ProgressBar

    if target not in ("agent", "objectives"):
        raise ConfigError(f"--target {target!r}: unknown target; use agent or objectives")
    if out.suffix != ".pt":
        raise ConfigError(f"-o {out}: a scorer checkpoint ends in .pt; pass e.g. -o learned-g.pt")
    card_path = out.with_suffix(".json")
    output_file(out, "-o", "gdata train", force=force, inputs=data)
    output_file(card_path, "-o", "gdata train", force=force, inputs=data, name=f"the card {card_path}")
    configure_torch()
    cfg = TrainConfig(data=[str(d) for d in data], out=str(out), seed=seed, epochs=epochs, hidden=hidden,
                      layers=layers, lr=lr, heldin=heldin, target=target)
    with recording([out, card_path], None, "gdata train"), ProgressBar("training the scorer", epochs) as bar:
        card = run_train(cfg, progress=lambda epoch: bar.update(epoch), command=command_line())
        atomic_write_text(card_path, json.dumps(card, indent=1) + "\n")
    sel = card["selection"]
    what = "drop" if target == "agent" else "objective gain"
    Console().print(f"{card['data']['rows']} rows from {card['data']['houses']} houses; epoch {sel['epoch']} chosen on "
                    f"{len(card['data']['heldin_houses'])} held-in houses: {what} of the chosen edit "
                    f"{sel['heldin']['chosen']:+.4f} (random pick {sel['heldin']['random']:+.4f}, best "
                    f"{sel['heldin']['best']:+.4f}); wrote {out} and {card_path}", highlight=False)


def register(app: typer.Typer, bench: typer.Typer) -> None:
    app.add_typer(gdata_app, name="gdata")
