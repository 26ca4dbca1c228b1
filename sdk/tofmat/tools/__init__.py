"""Tools built on the core: simulated sweeps, benchmarks, plots, the demo."""
