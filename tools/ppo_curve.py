"""Print a PPO run's held-in learning curve from its metrics.csv as a Markdown table.

Usage: python tools/ppo_curve.py RUN_DIR/metrics.csv

Each periodic evaluation (``--eval-every``) scores the same training-house episodes, the first one
before any update (pi_0), so the rows are paired. The run's last row, the final evaluation on other
episodes with the calibrated end threshold, is printed below the table.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path


def curve_rows(path: Path) -> tuple[list[dict[str, str]], dict[str, str] | None]:
    """(the periodic evaluations, the final evaluation row or None) of a PPO metrics.csv."""
    rows = [r for r in csv.DictReader(path.open(encoding="utf-8")) if r.get("eval/success")]
    final = rows[-1] if rows and not rows[-1].get("charts/SPS") and rows[-1]["frames"] != "0" else None
    return (rows[:-1] if final else rows), final


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("metrics", type=Path, help="a PPO run's metrics.csv")
    args = parser.parse_args()
    rows, final = curve_rows(args.metrics)
    print("| frames | held-in success | SPL | KL(pi \\|\\| pi_0), last update | training-episode success |")
    print("|---|---|---|---|---|")
    for r in rows:
        kl, ts = r.get("losses/kl_anchor"), r.get("charts/episode_success")
        print(f"| {int(r['frames']):,} | {float(r['eval/success']):.3f} | {float(r['eval/spl']):.3f} | "
              f"{float(kl):.4f} | {float(ts):.2f} |" if kl else
              f"| {int(r['frames']):,} | {float(r['eval/success']):.3f} | {float(r['eval/spl']):.3f} | | |")
    if final:
        print(f"\nfinal evaluation ({int(final['frames']):,} frames): success {float(final['eval/success']):.3f}, "
              f"SPL {float(final['eval/spl']):.3f}")


if __name__ == "__main__":
    main()
