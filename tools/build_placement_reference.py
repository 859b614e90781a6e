"""Rebuild the placement model's shipped reference (``src/adaptenv/adapt/data/placement_reference.json``).

Usage: python tools/build_placement_reference.py [--houses 300] [--seed 0] [-o PATH] [--from HOUSES.jsonl.gz]

By default it fits the model (:mod:`adaptenv.adapt.placement_model`) on ``--houses`` houses of adaptenv's
procedural generator (``generate_houses(N, SEED)``, default config): per object type, placement class and over all
objects, the count and the 1st, 50th and 99th percentiles of each feature. ``--from`` fits it on a house dataset
instead (one house JSON object a line); ``adaptenv audit --reference`` reads either the written JSON or such a
dataset.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from adaptenv.adapt.placement_model import REFERENCE_RESOURCE, load_model, procedural_reference

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "src" / "adaptenv" / "adapt" / REFERENCE_RESOURCE


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--houses", type=int, default=300, help="procedural houses to fit on")
    parser.add_argument("--seed", type=int, default=0, help="root seed of the procedural houses")
    parser.add_argument("--from", dest="source", type=Path, default=None, help="fit on this house dataset instead")
    parser.add_argument("-o", "--out", type=Path, default=DEFAULT_OUT, help="where to write the reference JSON")
    args = parser.parse_args()
    model = load_model(args.source) if args.source else procedural_reference(args.houses, args.seed)
    print(f"{model.save(args.out)}: {model.source}, {model.houses} houses, {len(model.stats)} keys")


if __name__ == "__main__":
    main()
