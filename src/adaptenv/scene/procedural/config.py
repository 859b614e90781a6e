"""The knobs of procedural generation: one dataclass, each field one line, checked before use."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from adaptenv.errors import AdaptenvError, ConfigError
from adaptenv.scene.assets import ROOM_TYPES
from adaptenv.vocabulary import AGENT_RADIUS

MIN_ROOMS, MAX_ROOMS = 1, 10
SPLITS = ("train", "val", "test")


class GenerationError(AdaptenvError):
    """Generation gave up: no attempt produced a house meeting every guarantee."""


class StageFailed(Exception):
    """A stage could not complete this attempt (internal: the pipeline retries with a derived seed)."""


@dataclass(frozen=True)
class GenerationConfig:
    """How procedural houses are generated (ProcTHOR-style); defaults give 2-6 room houses."""

    n_rooms: int | None = None
    """Number of rooms (1-10); None draws it from ``room_range``."""
    room_range: tuple[int, int] = (2, 6)
    """Inclusive range the room count is drawn from when neither ``n_rooms`` nor ``room_types`` is set."""
    room_types: tuple[str, ...] | None = None
    """Exact room types (Kitchen, LivingRoom, Bedroom, Bathroom), overriding ``n_rooms``."""
    cell_size: tuple[float, float] = (1.6, 2.2)
    """Range (m) of the floor-plan grid cell size, drawn once per house (ProcTHOR: 1.6-2.2 m)."""
    wall_height: tuple[float, float] = (2.5, 3.0)
    """Range (m) of the ceiling height, drawn once per house."""
    furniture_density: float = 1.0
    """Scales the number of filler objects per room (0 places only the priority furniture)."""
    edge_margin: float = 0.5
    """Free depth (m) kept in front of objects standing against a wall."""
    middle_margin: float = 0.35
    """Free border (m) kept around objects standing in the middle of a room."""
    passage: float = 0.5
    """Free width (m) kept between a mid-room object and every wall, so it never closes off a corner."""
    wall_gap: float = 0.02
    """Gap (m) between a wall and the back of the furniture standing against it."""
    object_gap: float = 0.01
    """Minimum gap (m) between two floor footprints, so rounding never makes them overlap."""
    door_clearance: float = 0.6
    """Depth (m) kept free in front of every door, doorframe and open wall, on both sides."""
    door_side_clearance: float = 0.15
    """Extra width (m) kept free on each side of a door's hole."""
    split: str = "train"
    """ProcTHOR asset split to draw from (train, val, test); split-less assets are always allowed."""
    open_kitchen_prob: float = 0.35
    """Probability that a kitchen-living (or living-living) connection is an open, empty wall."""
    doorframe_prob: float = 0.35
    """Probability that such a public connection is a leafless doorframe (when it is not open)."""
    extra_door_prob: float = 0.3
    """Probability of an extra door between two adjacent public rooms beyond the spanning tree."""
    closed_door_prob: float = 0.0
    """Probability that an interior door with a leaf is closed (openness 0): the rooms behind closed doors are out
    of the agent's reach and sight, as in a home with shut bedroom doors. 0 in every training preset."""
    window_prob: float = 0.6
    """Probability that an exterior wall segment long enough for a window gets one."""
    min_target_types: int = 3
    """Minimum number of ObjectNav target types with a reachable instance in every house."""
    agent_radius: float = AGENT_RADIUS
    """Radius (m) of the agent disc used for the reachability guarantees."""
    target_reach: float = 1.5
    """A target instance counts as reachable when a navigable cell lies within this distance (m)."""
    max_attempts: int = 25
    """Attempts (each with a derived seed) before generation raises GenerationError."""
    priority_types: dict[str, tuple[str, ...]] = field(default_factory=lambda: {
        "Bedroom": ("Bed", "Dresser"),
        "LivingRoom": ("Television", "Sofa", "DiningTable"),
        "Kitchen": ("CounterTop", "Fridge"),
        "Bathroom": ("Toilet", "Sink"),
    })
    """Types placed first in each room type, in order (ProcTHOR's priority lists)."""
    essential_types: dict[str, tuple[str, ...]] = field(default_factory=lambda: {
        "Bedroom": ("Bed",), "LivingRoom": ("Sofa",), "Kitchen": ("Fridge",), "Bathroom": ("Toilet",),
    })
    """Types every room of a type must get; a room is refurnished (then the attempt retried) until it does."""

    def with_rooms(self, rooms: int | str | None) -> GenerationConfig:
        """A copy with a room count (``5``) or an explicit type list (``"Kitchen,LivingRoom"``)."""
        if rooms is None:
            return self
        if isinstance(rooms, int):
            return replace(self, n_rooms=rooms, room_types=None)
        text = str(rooms).strip()
        if text.isdigit():
            return replace(self, n_rooms=int(text), room_types=None)
        types = tuple(t.strip() for t in text.split(",") if t.strip())
        return replace(self, room_types=types, n_rooms=None)

    def check(self) -> GenerationConfig:
        """Raise ConfigError naming the first invalid field and its fix; returns self."""
        if self.room_types is not None:
            bad = [t for t in self.room_types if t not in ROOM_TYPES]
            if bad:
                raise ConfigError(f"room_types: unknown room type {bad[0]!r}; use {', '.join(ROOM_TYPES)}")
            if not MIN_ROOMS <= len(self.room_types) <= MAX_ROOMS:
                raise ConfigError(f"room_types: {len(self.room_types)} rooms given; give {MIN_ROOMS} to {MAX_ROOMS}")
        if self.n_rooms is not None and not MIN_ROOMS <= self.n_rooms <= MAX_ROOMS:
            raise ConfigError(f"n_rooms: expected {MIN_ROOMS} to {MAX_ROOMS} rooms, got {self.n_rooms}; "
                              "pick a count in that range")
        lo, hi = self.room_range
        if not MIN_ROOMS <= lo <= hi <= MAX_ROOMS:
            raise ConfigError(f"room_range: expected {MIN_ROOMS} <= low <= high <= {MAX_ROOMS}, got {self.room_range}")
        if not 1.2 <= self.cell_size[0] <= self.cell_size[1] <= 5.0:
            raise ConfigError(f"cell_size: expected 1.2 <= low <= high <= 5.0 m, got {self.cell_size}")
        if self.split not in SPLITS:
            raise ConfigError(f"split: unknown asset split {self.split!r}; use one of {', '.join(SPLITS)}")
        if self.furniture_density < 0:
            raise ConfigError(f"furniture_density: expected >= 0, got {self.furniture_density}")
        if self.max_attempts < 1:
            raise ConfigError(f"max_attempts: expected >= 1, got {self.max_attempts}")
        return self
