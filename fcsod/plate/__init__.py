"""A job's build volume: the ``[build]`` models, reading and writing 3MF, voxels, and placing the finger copies.

This ``__init__`` imports nothing: a submodule loads only what it needs.
"""
