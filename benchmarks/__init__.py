"""Benchmarks: scripts that print figures (ratios against a baseline measured in the same run).

Run all with `python -m benchmarks.run [--short]`; each writes results/<name>.json.
"""
