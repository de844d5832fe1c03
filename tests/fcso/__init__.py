"""Tests of the method and its outputs (fcso), fast enough to run often."""
