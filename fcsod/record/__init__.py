"""Recording a job to MCAP (:mod:`~fcsod.record.recorder`), the Foxglove scenes, and the audit of a finished job.

This ``__init__`` imports nothing: a submodule loads only what it needs.
"""
