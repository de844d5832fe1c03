"""The zenoh bus: the session, the messages and their keys, Ed25519 signing, the local PKI and the ROS 2 form of the
messages.

This ``__init__`` imports nothing: a submodule loads only what it needs.
"""
