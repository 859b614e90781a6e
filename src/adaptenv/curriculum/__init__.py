"""The closed loop's curriculum: the loop itself, how levels are chosen, replayed and edited, where jobs run.

- :mod:`adaptenv.curriculum.loop`: ``run_loop`` and ``LoopConfig``, the loop for one method and seed.
- :mod:`adaptenv.curriculum.jobs`: its parallel work (evaluation, rollouts, generation) as picklable jobs.
- :mod:`adaptenv.curriculum.experiment`: methods x seeds, per-seed CSVs, summary with paired tests, plots.
- :mod:`adaptenv.curriculum.verdict`: the experiment's verdict line (reference minus each method, paired
  over held-out episodes, and whether the difference is within noise).
- :mod:`adaptenv.curriculum.records`: what a run writes to disk (typed records, folder layout).
- :mod:`adaptenv.curriculum.buffer`: the PLR-robust / ACCEL level buffer as data plus pure
  functions (insertion, rank-and-staleness replay distribution, parent selection, regret scores).
- :mod:`adaptenv.curriculum.executor`: one ``Executor`` interface (in process, a spawned process
  pool, or Ray) through which rollouts, evaluation and generation run.

Nothing is imported here, so ``import adaptenv.curriculum`` stays light (workers import it too).
"""
