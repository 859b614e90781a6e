"""Label placement: the obstacle store's kind column and what each kind costs a label."""

from __future__ import annotations

import numpy as np
import pytest

from adaptenv.render.labels import COSTS, Kind, Obstacles

IMAGE = (0.0, 0.0, 400.0, 400.0)


def test_every_kind_has_costs_and_records_carry_their_kind():
    assert set(COSTS) == set(Kind)
    obst = Obstacles(IMAGE, IMAGE)
    obst.add([(10, 10, 20, 20), (30, 30, 40, 40)], Kind.FURNITURE, owner=0)
    obst.add((50, 50, 60, 60), Kind.MARKER)
    obst.add_points([(5.0, 5.0)], Kind.PATH)
    assert obst.boxes.rows[:, 4].tolist() == [Kind.FURNITURE, Kind.FURNITURE, Kind.MARKER]
    assert obst.boxes.rows[2, 5:].tolist() == [COSTS[Kind.MARKER].cover, COSTS[Kind.MARKER].touch]
    # Furniture boxes bring their edges as segments owned by their rows; markers have none.
    segs = obst.segs.rows
    assert len(segs) == 8 and set(segs[:, 4]) == {Kind.FURNITURE} and sorted(set(segs[:, 6])) == [0, 1]
    assert obst.points.rows[0, 2:].tolist() == [Kind.PATH, COSTS[Kind.PATH].point]


@pytest.mark.parametrize("kind", [Kind.MARKER, Kind.LABEL, Kind.ANCHOR, Kind.FURNITURE])
def test_covering_an_obstacle_costs_its_kinds_cover_and_touch(kind):
    obst = Obstacles(IMAGE, IMAGE)
    obst.add((100, 100, 120, 110), kind)
    cand = np.array([[100.0, 100.0, 120.0, 110.0], [200.0, 200.0, 220.0, 210.0]])  # on it, far from it
    cost = obst.cost(cand, None, np.zeros(2))
    assert cost[0] - cost[1] == pytest.approx(COSTS[kind].cover + COSTS[kind].touch)


def test_a_label_nearer_to_other_furniture_pays_only_for_furniture_neighbours():
    """The 'reads as another object's label' penalty looks at the kind column, not at cost values."""
    def cost_next_to(kind: Kind) -> float:
        obst = Obstacles(IMAGE, IMAGE)
        obst.add([(100, 100, 110, 110)], Kind.FURNITURE, owner=0)  # the labelled object (row 0)
        obst.add((140, 100, 150, 110), kind)  # something right next to the candidate
        # Two candidates: the one scored, and one whose extent takes the neighbour into view.
        cand = np.array([[125.0, 100.0, 138.0, 110.0], [145.0, 100.0, 158.0, 110.0]])
        return float(obst.cost(cand, (105.0, 105.0), np.zeros(2), own=0)[0])

    furniture, room_name = cost_next_to(Kind.FURNITURE), cost_next_to(Kind.ROOM_NAME)
    assert furniture - room_name == pytest.approx(2.0)
