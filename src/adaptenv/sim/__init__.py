"""The navigation simulator: compiled worlds, physics, the scan, batched stepping and Gymnasium envs.

``import adaptenv`` registers the Gymnasium ids below (:mod:`adaptenv._gym`; entry points are
strings, so the simulator loads only when an env is made):

- ``adaptenv/ObjectNav-v0``: :class:`adaptenv.sim.env.NavEnv`; ``gymnasium.make_vec(...,
  vectorization_mode="vector_entry_point")`` gives the native batched
  :class:`adaptenv.sim.env.NavVectorEnv`.
"""

from __future__ import annotations

OBJECTNAV_ID = "adaptenv/ObjectNav-v0"
