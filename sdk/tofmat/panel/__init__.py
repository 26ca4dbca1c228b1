# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The standalone box's front panel: what its 128x64 OLED shows (:class:`PanelView`).

``tofmat panel`` (tofmat.tools.panel_agent) keeps a view up to date from tofmatd's events and draws
it on an SSD1306 (tofmat.hw). The panel's button is tofmatd's (``--reset-button``, on the daemon's
GPIO): a press resets the accumulation and the panel shows it from the ``reset`` stream.
"""

from __future__ import annotations

from .view import COLUMNS, PanelView

__all__ = ["COLUMNS", "PanelView"]
