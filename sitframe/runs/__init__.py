"""Runs: the control loop, the run driver and everything that schedules trials.

What it holds
    :mod:`~sitframe.runs.loop` (one trial: the control loop, its arrays, its scores),
    :mod:`~sitframe.runs.fused` and :mod:`~sitframe.runs.fused_kernels` (the same loop
    compiled, for a trial whose step is all built-ins),
    :mod:`~sitframe.runs.tracker` (the core's side of situations that change in a trial),
    :mod:`~sitframe.runs.collect` (the collect stage), :mod:`~sitframe.runs.experiment`
    (an experiment's stages in order, reported to the observers),
    :mod:`~sitframe.runs.parallel` (trials on a process pool or a Dask cluster, results
    bit-identical), :mod:`~sitframe.runs.prepare` (a run from a config, with the logs it
    reuses), :mod:`~sitframe.runs.prepare` (finishing an interrupted run),
    :mod:`~sitframe.runs.sweep` (a grid of config values x seeds) and
    :mod:`~sitframe.runs.evaluation` (a log's frozen policies evaluated in any world).

What it may import
    :mod:`sitframe.logs`, :mod:`sitframe.contract`, :mod:`sitframe.learning`,
    :mod:`sitframe.situations`, :mod:`sitframe.sim` and the ground floor; never
    :mod:`sitframe.analysis` (analysis reads what runs wrote), :mod:`sitframe.gym` or
    :mod:`sitframe.cli`.

Entry points
    :func:`~sitframe.runs.prepare.prepare_experiment`,
    :class:`~sitframe.runs.experiment.Experiment`, :func:`~sitframe.runs.sweep.run_sweep`,
    :func:`~sitframe.runs.evaluation.evaluate_log`, :func:`~sitframe.runs.parallel.make_executor`.
"""
