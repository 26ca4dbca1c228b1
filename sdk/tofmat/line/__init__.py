# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The sorting line's agents beside tofmatd: the diverter gates (:mod:`tofmat.line.gates`)."""

from __future__ import annotations

from .gates import Gate, GateMove, GateSchedule, parse_gate

__all__ = ["Gate", "GateMove", "GateSchedule", "parse_gate"]
