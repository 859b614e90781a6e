"""The simulator's fixed interface: agent body, actions, observation layout and semantic classes.

A neural policy reads observations in exactly this layout; changing anything here changes the
observation format (bump ``OBSERVATION_VERSION``).

Observation (one agent, a ``gymnasium.spaces.Dict``):

- ``depth``: float32 (N_RAYS,), distance to the first obstacle along each ray divided by
  MAX_RANGE, 1.0 when nothing is hit within range. Ray k points at yaw + FOV * (k / (N_RAYS-1) - 1/2),
  so ray 0 is the leftmost.
- ``semantic``: int64 (N_RAYS,), class id of what each ray hit (CLASS_NONE when nothing).
- ``target``: int64 scalar, class id of the target object type.
- ``prev_action``: int64 scalar, the previous action (NO_ACTION at the start of an episode).
- ``collided``: int64 scalar, 1 when the previous move was blocked.
"""

from __future__ import annotations

from functools import lru_cache

from adaptenv.scene.assets import load_catalog
from adaptenv.vocabulary import AGENT_RADIUS, TARGET_TYPES

__all__ = ["AGENT_RADIUS", "TARGET_TYPES"]  # re-exported: the agent body and targets are part of the sim's interface

OBSERVATION_VERSION = 1

MOVE_STEP = 0.2
ROTATE_LARGE = 30.0
ROTATE_SMALL = 6.0
MAX_STEPS = 600
SUCCESS_DISTANCE = 2.0
"""A target counts as found within this distance (m) when visible."""

ACTIONS = ("m", "b", "l", "r", "ls", "rs", "end")
"""SPOC's navigation subset: move ahead/back 0.2 m, rotate left/right 30 deg, left/right 6 deg, end."""
ACTION_NAMES = ("move_ahead", "move_back", "rotate_left", "rotate_right", "rotate_left_small",
                "rotate_right_small", "end")
MOVE_AHEAD, MOVE_BACK, ROTATE_LEFT, ROTATE_RIGHT, ROTATE_LEFT_SMALL, ROTATE_RIGHT_SMALL, END = range(7)
N_ACTIONS = len(ACTIONS)
NO_ACTION = N_ACTIONS
"""Value of ``prev_action`` at the first step."""
YAW_DELTA = (0.0, 0.0, -ROTATE_LARGE, ROTATE_LARGE, -ROTATE_SMALL, ROTATE_SMALL, 0.0)
"""Yaw change of each action in degrees (left turns decrease yaw, as in AI2-THOR)."""
MOVE_DELTA = (MOVE_STEP, -MOVE_STEP, 0.0, 0.0, 0.0, 0.0, 0.0)

N_RAYS = 32
FOV_DEG = 90.0
MAX_RANGE = 5.0

CLASS_NONE, CLASS_WALL, CLASS_DOOR, CLASS_WINDOW = 0, 1, 2, 3
_FIRST_OBJECT_CLASS = 4


@lru_cache(maxsize=1)
def object_classes() -> tuple[str, ...]:
    """Object types with a class id: ``class_id(t) = 4 + object_classes().index(t)``."""
    return load_catalog().object_types


def class_id(object_type: str) -> int:
    """Semantic class id of an object type (stable: types are sorted by name)."""
    return _FIRST_OBJECT_CLASS + object_classes().index(object_type)


def n_classes() -> int:
    return _FIRST_OBJECT_CLASS + len(object_classes())


