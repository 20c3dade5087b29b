"""Benchmarks: ``python -m bench <part>``; each part writes JSON to bench/results/."""
