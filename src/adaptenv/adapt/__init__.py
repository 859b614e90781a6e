"""Adaptive environment generation: analyze a trajectory (F), edit the scene (G), keep it plausible.

- :mod:`adaptenv.adapt.analysis`: the trajectory analysis F (outcome, concerns, suggestions).
- :mod:`adaptenv.adapt.edits`: :class:`~adaptenv.adapt.edits.Edit` records, :class:`EditLog`, replay.
- :mod:`adaptenv.adapt.placement`: the paper's collision-aware placement (march toward the proposed
  pose, stop before the first collision).
- :mod:`adaptenv.adapt.validation`: ``validate_scene`` (every problem of an edited scene) and the
  fast ``EditValidator`` generators use.
- :mod:`adaptenv.adapt.realism`: a realism score in [0, 1] from ProcTHOR's placement annotations.

Nothing heavy is imported here; import the submodules you need.
"""
