"""The simulator: worlds, the robot, its sensors' geometry, and the compiled kernels.

What it holds
    :mod:`~sitframe.sim.world` (the TOML world format and its loader),
    :mod:`~sitframe.sim.geometry` (ray casting, distances, polygons),
    :mod:`~sitframe.sim.robot` (the Pioneer 2DX disc: motion, collisions, recovery),
    :mod:`~sitframe.sim.fleet` (N robots stepped together),
    :mod:`~sitframe.sim.paths` (shortest collision-free paths, the reference of SPL),
    :mod:`~sitframe.sim.metrics` (figures of a trajectory: collisions per 1000, coverage, SPL),
    :mod:`~sitframe.sim.draw` (a world drawn with matplotlib),
    :mod:`~sitframe.sim.kernels` and :mod:`~sitframe.sim.kernels_numba` (the hot loops
    compiled by numba, bit-identical to their numpy twins; the situations and learning
    layers use them too), :mod:`~sitframe.sim.numpy_loops` (numpy's own float64 loops and
    OpenBLAS's ``ddot``, for kernels that must give numpy's bits),
    :mod:`~sitframe.sim.numba_cache` (where numba caches them),
    :mod:`~sitframe.sim.fastinit` (the cheaper ``__init__`` of the records built every
    iteration, the contract's too).

What it may import
    Only the ground floor (:mod:`sitframe.errors`, :mod:`sitframe.params`). The simulator
    knows nothing of situations, learning, plugins, runs or logs (checked by import-linter).

Entry points
    :func:`~sitframe.sim.world.load_world`, :class:`~sitframe.sim.robot.Simulator`,
    :func:`~sitframe.sim.robot.step_robot`, :func:`~sitframe.sim.geometry.rim_ranges`.
"""
