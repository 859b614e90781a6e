"""How far shutting interior doors moves the agent's success (held-in houses only).

    NUMBA_NUM_THREADS=1 python docs/results/target-success/doors.py [HOUSES [N]]   # default preset:pretrain-train 8

For each of the first N houses: the ``pretrained`` agent's success on the 20 episodes difficulty on request
measures (``measurement_episodes(world, 20, 0)``), on 3 fresh action draws each; then every open interior door shut
alone, kept only when the house still validates against the original and every measured episode stays solvable
(as ``adapt_to_success`` checks an edit); then those doors shut together, one by one in order of their single
effect, each kept while every episode stays solvable. One line per house.
"""

from __future__ import annotations

import sys

from adaptenv.adapt.target import _checked, fresh_measurement, measurement_episodes
from adaptenv.agents.houses import load_house_set
from adaptenv.agents.network import configure_torch
from adaptenv.agents.registry import resolve_policy
from adaptenv.scene.model import is_interior_leaf_door, is_shut, set_door_openness
from adaptenv.sim.world import compile_world


def shut(house, door_id: str):
    """A copy of ``house`` with one door shut."""
    h = house.model_copy(deep=True)
    set_door_openness(h, door_id, 0.0)
    return h


def main(houses: str, n: int) -> None:
    configure_torch()
    hs, agent = load_house_set(houses), resolve_policy("pretrained", seed=0)
    total = shuttable = 0
    for name, house in list(zip(hs.names, hs.houses, strict=True))[:n]:
        world = compile_world(house, name)
        eps = measurement_episodes(world, 20, 0)
        before = fresh_measurement(world, eps, agent).success
        doors = [d.id for d in house.doors if is_interior_leaf_door(d) and not is_shut(d)]
        single = {}
        for d in doors:
            _, w = _checked(shut(house, d), house, eps, 0, name)
            if w is not None:
                single[d] = fresh_measurement(w, eps, agent).success
        cur, closed, w_all = house, [], world
        for d in sorted(single, key=single.get):
            _, w = _checked(shut(cur, d), house, eps, 0, name)
            if w is not None:
                cur, closed, w_all = shut(cur, d), closed + [d], w
        together = fresh_measurement(w_all, eps, agent).success if closed else before
        total, shuttable = total + len(doors), shuttable + len(single)
        each = ", ".join(f"{d} {s:.2f}" for d, s in single.items()) or "none"
        print(f"{name}: success {before:.2f}; open interior doors {len(doors)}, of them {len(single)} can be shut with every "
              f"episode solvable ({each}); all of them shut: {together:.2f}", flush=True)
    print(f"{shuttable} of {total} open interior doors can be shut with every measured episode solvable")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "preset:pretrain-train", int(sys.argv[2]) if len(sys.argv) > 2 else 8)
