"""Constants every layer shares (scene, sim, adapt): the agent's body, the target types, object categories.

This module imports nothing from adaptenv, so the scene layer (procedural houses) and the layers
above it read the same numbers without importing each other upward.
"""

from __future__ import annotations

AGENT_RADIUS = 0.2
"""Agent body: a disc of this radius (m)."""

#: ObjectNav target types adaptenv uses: ProcTHOR's standard floor-standing targets plus Fridge
#: (the paper's example). Small objects are not targets because the scan sees floor furniture only.
TARGET_TYPES = ("Bed", "Chair", "Fridge", "GarbageCan", "HousePlant", "Sofa", "Television", "Toilet")

SEAT_TYPES = frozenset({"Chair", "Stool", "ArmChair"})
"""Seats: they may stand partly under a table (validation allows that overlap)."""
TABLE_TYPES = frozenset({"DiningTable", "Desk", "CoffeeTable", "SideTable"})
"""Tables a seat may overlap."""
CHAIR_TABLE_TYPES = frozenset({"DiningTable", "Desk"})
"""Tables procedural houses set chairs around."""
