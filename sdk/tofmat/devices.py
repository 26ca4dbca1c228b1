# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The Kinect v2 cameras on this machine's USB bus (what `tofmat devices` lists)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from . import _tofmat


@dataclass(frozen=True)
class Device:
    """One Kinect v2 on the USB bus."""

    bus: int  #: USB bus number
    port: str  #: USB port path, as in ``/sys/bus/usb/devices`` (for example ``2-1.3``)
    product_id: int  #: 0x02d8 (Kinect for Windows v2) or 0x02c4 (Kinect for Xbox One)
    serial: str  #: the camera's serial number ("" when it could not be read)
    accessible: bool  #: whether this user may open it
    problem: str  #: why it cannot be opened ("" when accessible)

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def devices() -> list[Device]:
    """Every Kinect v2 on the USB bus, usable or not; an empty list when there is none.

    Raises tofmat.UsbError when libusb cannot start (no USB access at all).
    """
    return [
        Device(
            bus=int(d["bus"]),
            port=str(d["port"]),
            product_id=int(d["product_id"]),
            serial=str(d["serial"]),
            accessible=bool(d["accessible"]),
            problem=str(d["problem"]),
        )
        for d in _tofmat.kinect.list_devices()
    ]


__all__ = ["Device", "devices"]
