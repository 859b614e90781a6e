"""How far the agent's measured success moves with its action draws alone, on unedited houses.

    NUMBA_NUM_THREADS=1 python docs/results/target-success/noise.py [HOUSES [DRAWS [STRIDE]]] > noise.txt

For the first ``HOUSES`` (4) houses of ``preset:pretrain-train`` (held in), the ``pretrained`` agent (seed 0) runs
the 20 measured episodes of :func:`adaptenv.adapt.target.measurement_episodes` (seed 0) ``DRAWS`` (6) times, each
time with the sampling seeds offset by ``STRIDE`` per draw (default ``DRAW_SEED_STRIDE``, as
:func:`adaptenv.adapt.target.drawn` offsets them). Printed per house: the success of each draw of the 20
episodes, and each episode's share of successful draws.
"""

from __future__ import annotations

import sys

import numpy as np


def main(houses: int = 4, draws: int = 6, stride: int | None = None) -> None:
    from adaptenv.adapt.target import DRAW_SEED_STRIDE, drawn, measure, measurement_episodes
    from adaptenv.agents.houses import load_house_set
    from adaptenv.agents.network import configure_torch
    from adaptenv.agents.registry import resolve_policy
    from adaptenv.sim.world import compile_world

    configure_torch()
    hs = load_house_set("preset:pretrain-train")
    policy = resolve_policy("pretrained", seed=0)
    for name, house in list(zip(hs.names, hs.houses, strict=True))[:houses]:
        world = compile_world(house, name)
        eps = measurement_episodes(world, 20, 0)
        m, _ = measure(world, drawn(eps, draws, stride or DRAW_SEED_STRIDE), policy)
        ok = np.array(m.successes, float).reshape(draws, len(eps))
        print(f"{name}: success of each draw of the 20 episodes {' '.join(f'{x:.2f}' for x in ok.mean(1))} "
              f"(range {ok.mean(1).max() - ok.mean(1).min():.2f}); per episode {' '.join(f'{x:.2f}' for x in ok.mean(0))}")


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:4]))
