"""The navigation simulator: compiled worlds, physics, the scan, batched stepping and Gymnasium envs.

Importing this package registers the Gymnasium ids below (entry points are strings, so the
simulator itself loads only when an env is made):

- ``adaptenv/ObjectNav-v0``: :class:`adaptenv.sim.env.NavEnv`; ``gymnasium.make_vec(...,
  vectorization_mode="vector_entry_point")`` gives the native batched
  :class:`adaptenv.sim.env.NavVectorEnv`.
"""

from __future__ import annotations

import gymnasium

OBJECTNAV_ID = "adaptenv/ObjectNav-v0"

if OBJECTNAV_ID not in gymnasium.registry:
    gymnasium.register(id=OBJECTNAV_ID, entry_point="adaptenv.sim.env:NavEnv",
                       vector_entry_point="adaptenv.sim.env:NavVectorEnv", disable_env_checker=False)
