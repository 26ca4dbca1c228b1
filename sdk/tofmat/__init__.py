# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""tofmat: material classification from Time-of-Flight depth distortion.

Implements Tanaka et al., "Material Classification using Frequency- and
Depth-Dependent Time-of-Flight Distortion" (CVPR 2017) on a C++ core:

>>> import tofmat
>>> table = tofmat.ExemplarTable.from_npy_dir("shared/data/tanaka2017_kinect2_db")
>>> clf = tofmat.Classifier(table)  # the session-robust matcher; method="eq12": the paper's
>>> clf.classify(table.features[0]).material
'acryl'

The core needs numpy only (and click for the `tofmat` command); the simulator's calibration and
evaluation need the ``sim`` extra, the plots the ``plot`` extra (``pip install 'tofmat[all]'``):
without them those raise :class:`MissingExtraError` (an ImportError) naming what to install.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from ._extras import MissingExtraError
from ._tofmat import (
    SPEED_OF_LIGHT_MM_PER_NS,
    BinSpec,
    Calibration,
    ClassificationResult,
    Classifier,
    DepthBinAccumulator,
    ExemplarTable,
    FormatError,
    RankedMatch,
    SessionPrior,
    UsbError,
    curve_roughness,
    depth_from_phase_mm,
    read_npy,
    unambiguous_range_mm,
)
from .client import (
    AuthenticationError,
    Client,
    ClientError,
    CommandError,
    ConnectionClosedError,
    DaemonTimeoutError,
    DaemonUnavailableError,
    NotPermittedError,
    ProtocolError,
    ProtocolVersionError,
)
from .devices import Device, devices
from .geometry import Intrinsics

try:
    __version__ = version("tofmat")
except PackageNotFoundError:  # running from a source tree without installing
    __version__ = "0+unknown"

__all__ = [
    "SPEED_OF_LIGHT_MM_PER_NS",
    "AuthenticationError",
    "BinSpec",
    "Calibration",
    "ClassificationResult",
    "Classifier",
    "Client",
    "ClientError",
    "CommandError",
    "ConnectionClosedError",
    "DaemonTimeoutError",
    "DaemonUnavailableError",
    "DepthBinAccumulator",
    "Device",
    "ExemplarTable",
    "FormatError",
    "Intrinsics",
    "MissingExtraError",
    "NotPermittedError",
    "ProtocolError",
    "ProtocolVersionError",
    "RankedMatch",
    "SessionPrior",
    "UsbError",
    "__version__",
    "curve_roughness",
    "depth_from_phase_mm",
    "devices",
    "read_npy",
    "unambiguous_range_mm",
]
