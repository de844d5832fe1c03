"""End-to-end tests: the daemon runs (marker ``e2e``)."""
