# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""`tofmat report`: error against run time of every path, and the fixed-point path's stability.

:func:`write_report` runs the benchmarks on this host (the Python SDK's classifier, the C++
``tofmat_bench_fixed`` and ``tofmat_bench_profiles``), computes the fixed-point classifier's stiff
cases against the float reference, and writes one Markdown file with PNG figures (matplotlib: the
``plot`` extra). :func:`pareto_front` is the front the figures draw. docs/report.md describes the
report.
"""

from __future__ import annotations

from .pareto import dominates, pareto_front
from .writer import REPORT_NAME, SECTIONS, ReportError, write_report

__all__ = ["REPORT_NAME", "SECTIONS", "ReportError", "dominates", "pareto_front", "write_report"]
