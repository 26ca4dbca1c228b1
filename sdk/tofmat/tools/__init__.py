# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Tools built on the core: simulated sweeps, benchmarks, plots, the demo."""
