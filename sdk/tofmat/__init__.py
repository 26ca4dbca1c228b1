"""tofmat: material classification from Time-of-Flight depth distortion.

Implements Tanaka et al., "Material Classification using Frequency- and
Depth-Dependent Time-of-Flight Distortion" (CVPR 2017) on a C++ core:

>>> import tofmat
>>> table = tofmat.ExemplarTable.from_npy_dir("shared/data/tanaka2017_kinect2_db")
>>> clf = tofmat.Classifier(table, backend="float")
>>> clf.classify(table.features[0]).material
'acryl'

The core needs numpy only (and click for the `tofmat` command); the simulator's calibration and
evaluation need the ``sim`` extra, the plots the ``plot`` extra (``pip install 'tofmat[all]'``):
without them those raise :class:`MissingExtraError` (an ImportError) naming what to install.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from ._tofmat import (
    SPEED_OF_LIGHT_MM_PER_NS,
    BinSpec,
    ClassificationResult,
    Classifier,
    DepthBinAccumulator,
    ExemplarTable,
    FormatError,
    RankedMatch,
    UsbError,
    depth_from_phase_mm,
    read_npy,
    unambiguous_range_mm,
)

from ._extras import MissingExtraError
from .client import (  # noqa: E402  (after the extension it wraps)
    AuthenticationError,
    Client,
    ClientError,
    CommandError,
    NotPermittedError,
    ConnectionClosedError,
    DaemonTimeoutError,
    DaemonUnavailableError,
    ProtocolError,
    ProtocolVersionError,
)

try:
    __version__ = version("tofmat")
except PackageNotFoundError:  # running from a source tree without installing
    __version__ = "0+unknown"

__all__ = [
    "AuthenticationError",
    "Client",
    "ClientError",
    "CommandError",
    "NotPermittedError",
    "ConnectionClosedError",
    "DaemonTimeoutError",
    "DaemonUnavailableError",
    "ProtocolError",
    "ProtocolVersionError",
    "SPEED_OF_LIGHT_MM_PER_NS",
    "BinSpec",
    "ClassificationResult",
    "Classifier",
    "DepthBinAccumulator",
    "ExemplarTable",
    "FormatError",
    "MissingExtraError",
    "RankedMatch",
    "UsbError",
    "depth_from_phase_mm",
    "read_npy",
    "unambiguous_range_mm",
    "__version__",
]
