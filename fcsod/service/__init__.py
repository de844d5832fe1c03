"""The daemon itself: its loop (:mod:`~fcsod.service.daemon`), the folder watcher, the job journal and its repair,
systemd's notifications.

This ``__init__`` imports nothing: a submodule loads only what it needs.
"""
