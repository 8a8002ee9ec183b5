"""Benchmarks (``voxwarp bench ...``). Product code never imports this package."""
