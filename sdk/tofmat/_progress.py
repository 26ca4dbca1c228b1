# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The progress callback that long jobs of the SDK take (the CLI turns it into a progress bar)."""

from __future__ import annotations

from typing import Protocol


class Progress(Protocol):
    """Told after each step of a long job: ``done`` of ``total`` steps, and what the step was."""

    def __call__(self, done: int, total: int, what: str = "") -> None: ...


__all__ = ["Progress"]
