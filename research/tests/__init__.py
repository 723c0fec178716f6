"""Tests of the research notes' numbers and of the study scripts: `python -m pytest research/tests`."""
