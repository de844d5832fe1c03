"""One job: its inputs (:mod:`~fcsod.job.inputs`), the worker process (:mod:`~fcsod.job.process`), the job's state
(:mod:`~fcsod.job.task`),
its steps (:mod:`~fcsod.job.steps`), running them and failing well (:mod:`~fcsod.job.running`), finger sets,
verification.

This ``__init__`` imports nothing: a submodule loads only what it needs.
"""
