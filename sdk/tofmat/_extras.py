# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Optional dependencies: what needs which extra, and one clear error when it is not installed.

The core (``import tofmat``, the client, tables, the classifier and their commands) needs numpy and
click only. The simulator's calibration and evaluation need ``tofmat[sim]`` (scipy, matplotlib for
their figures), the plots ``tofmat[plot]`` (matplotlib), the box's I2C peripherals on a real bus and
the front panel's text ``tofmat[hw]`` (smbus2, Pillow); ``tofmat[all]`` is all three. Code that uses an
optional package imports it inside the function that needs it, after :func:`require`::

    require("scipy", extra="sim", feature="tofmat sim calibrate")
    from scipy.optimize import least_squares
"""

from __future__ import annotations

import importlib
from types import ModuleType


class MissingExtraError(ImportError):
    """An optional dependency is not installed (or does not import); the message names the extra to install."""

    def __init__(self, module: str, extra: str, feature: str, reason: str | None = None) -> None:
        why = f" ({module} is installed but does not import: {reason})" if reason else ""
        super().__init__(f"{feature} needs {module}{why}: pip install 'tofmat[{extra}]'", name=module)
        self.module = module
        self.extra = extra
        self.feature = feature


def _is_missing(error: ImportError, module: str) -> bool:
    """True when ``error`` says that ``module`` (or one of its parent packages) is absent, not broken."""
    name = error.name or ""
    return isinstance(error, ModuleNotFoundError) and (module == name or module.startswith(name + "."))


def require(module: str, *, extra: str, feature: str) -> ModuleType:
    """Import ``module`` (e.g. "scipy.optimize") or raise :class:`MissingExtraError` naming ``extra``.

    ``feature`` is what needs it, as the user knows it (a command such as "tofmat plot table", or a
    function): the message reads "<feature> needs <module>: pip install 'tofmat[<extra>]'".
    """
    try:
        return importlib.import_module(module)
    except ImportError as e:
        reason = None if _is_missing(e, module) else str(e)
        raise MissingExtraError(module.partition(".")[0], extra, feature, reason) from e


def require_pyplot(*, extra: str, feature: str) -> None:
    """:func:`require` matplotlib and select its Agg backend (files only: never needs a display);
    the caller then imports ``matplotlib.pyplot``."""
    matplotlib = require("matplotlib", extra=extra, feature=feature)
    matplotlib.use("Agg")
