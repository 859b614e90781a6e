"""Print a policy's agreement with its teacher's labels on the teacher's, DAgger's and its own states.

    python tools/label_agreement.py [--checkpoint pretrained] [--teacher expert] [--houses preset:pretrain-train]
        [--seed 0] [--steps 256]

The table in docs/agent.md ("PPO", "Why") is this script's output.
"""

from __future__ import annotations

import argparse

from adaptenv.agents.checkpoint import load_checkpoint
from adaptenv.agents.houses import load_house_set
from adaptenv.agents.registry import init_checkpoint
from adaptenv.agents.teachers import TEACHERS, label_agreement
from adaptenv.sim.spec import ROTATE_LEFT, ROTATE_RIGHT


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", default="pretrained")
    parser.add_argument("--houses", default="preset:pretrain-train")
    parser.add_argument("--teacher", default="expert", help="who labels: " + ", ".join(TEACHERS))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--steps", type=int, default=256, help="steps of the 64 agents per beta")
    args = parser.parse_args()
    net = load_checkpoint(init_checkpoint(args.checkpoint)).net.eval()
    worlds = load_house_set(args.houses).worlds
    print("| beta | episodes | cross-entropy | accuracy | labels move ahead | labels turn 30 deg | argmax move ahead |")
    print("|---|---|---|---|---|---|---|")
    for beta in (1.0, 0.8, 0.0):
        a = label_agreement(net, worlds, beta, teacher=args.teacher, steps=args.steps, seed=args.seed)
        turn = a.label_share[ROTATE_LEFT] + a.label_share[ROTATE_RIGHT]
        print(f"| {beta} | {a.episodes} | {a.cross_entropy:.2f} | {a.accuracy:.2f} | {a.label_share[0]:.2f} "
              f"| {turn:.2f} | {a.argmax_share[0]:.2f} |")


if __name__ == "__main__":
    main()
