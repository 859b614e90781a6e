"""The closed loop's curriculum: how levels are chosen, replayed and edited, and where jobs run.

- :mod:`adaptenv.curriculum.buffer`: the PLR-robust / ACCEL level buffer as data plus pure
  functions (insertion, rank-and-staleness replay distribution, parent selection, regret scores).
- :mod:`adaptenv.curriculum.executor`: one ``Executor`` interface (in process, a spawned process
  pool, or Ray) through which rollouts, evaluation and generation run.

Nothing is imported here, so ``import adaptenv.curriculum`` stays light (workers import it too).
"""
