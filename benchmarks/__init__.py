"""Benchmarks of fcso (run with ``python -m benchmarks.<name>``)."""
