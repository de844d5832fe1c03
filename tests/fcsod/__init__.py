"""Tests of the daemon's parts (fcsod) without running the daemon."""
