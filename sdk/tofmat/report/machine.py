# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""What the report's figures were measured on: CPU, cores, OS, compiler, Python, numpy, date."""

from __future__ import annotations

import datetime
import importlib.metadata
import os
import platform
import re
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import __version__


@dataclass(frozen=True)
class Machine:
    date: str  # local time, ISO 8601 with the offset
    cpu: str
    cores: str
    os: str
    compiler: str
    cpp_build: str
    python: str
    numpy: str
    other: list[tuple[str, str]] = field(default_factory=list)  # (what, value): further lines

    def rows(self) -> list[tuple[str, str]]:
        return [
            ("date", self.date),
            ("CPU", self.cpu),
            ("cores", self.cores),
            ("OS", self.os),
            ("C++ compiler", self.compiler),
            ("C++ build (the benchmarks)", self.cpp_build),
            ("Python", self.python),
            ("numpy", self.numpy),
            *self.other,
        ]


def _read(path: Path) -> str:
    try:
        return path.read_text(errors="replace")
    except OSError:
        return ""


def _cpu() -> tuple[str, bool]:
    """The CPU's model name and whether it reports AVX2 (Linux: /proc/cpuinfo)."""
    info = _read(Path("/proc/cpuinfo"))
    model = re.search(r"^model name\s*:\s*(.+)$", info, re.M) or re.search(r"^Hardware\s*:\s*(.+)$", info, re.M)
    flags = re.search(r"^(?:flags|Features)\s*:\s*(.+)$", info, re.M)
    name = model.group(1).strip() if model else (platform.processor() or "unknown")
    return f"{name} ({platform.machine()})", bool(flags and "avx2" in flags.group(1).split())


def _os() -> str:
    rel = _read(Path("/etc/os-release"))
    m = re.search(r'^PRETTY_NAME="?([^"\n]+)"?$', rel, re.M)
    name = m.group(1) if m else platform.system()
    return f"{name}, kernel {platform.release()}"


def _cmake_cache(build_dir: Path) -> dict[str, str]:
    out: dict[str, str] = {}
    for line in _read(build_dir / "CMakeCache.txt").splitlines():
        m = re.match(r"^([A-Za-z0-9_]+):[A-Z]+=(.*)$", line)
        if m:
            out[m.group(1)] = m.group(2)
    return out


def _compiler_version(path: str) -> str:
    try:
        run = subprocess.run([path, "--version"], capture_output=True, text=True, timeout=10, check=False)
    except (OSError, subprocess.TimeoutExpired):
        return ""
    return run.stdout.splitlines()[0].strip() if run.returncode == 0 and run.stdout else ""


def _git_commit() -> str:
    """HEAD of the checkout in the working folder (read only), or "" outside one."""
    try:
        run = subprocess.run(
            ["git", "rev-parse", "--short=12", "HEAD"], capture_output=True, text=True, timeout=10, check=False
        )
    except (OSError, subprocess.TimeoutExpired):
        return ""
    return run.stdout.strip() if run.returncode == 0 else ""


def _version_of(package: str) -> str:
    try:
        return importlib.metadata.version(package)
    except importlib.metadata.PackageNotFoundError:
        return "not installed"


def describe_machine(build_dir: Path) -> Machine:
    """This host, and the C++ build in ``build_dir`` (its CMakeCache.txt) whose benchmarks the report runs."""
    cpu, avx2 = _cpu()
    n = os.cpu_count() or 0
    try:
        usable = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        usable = n
    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    cores = f"{n} logical ({usable} usable by this process); load average {load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f} at the start"
    cache = _cmake_cache(build_dir)
    cxx = cache.get("CMAKE_CXX_COMPILER", "")
    version = _compiler_version(cxx) if cxx else ""
    compiler = f"{version} ({cxx})" if version else (cxx or f"unknown (no {build_dir / 'CMakeCache.txt'})")
    build_type = cache.get("CMAKE_BUILD_TYPE", "")
    flags = cache.get(f"CMAKE_CXX_FLAGS_{build_type.upper()}", "") if build_type else ""
    cpp_build = f"{build_dir}: {build_type or 'unknown build type'}" + (f" ({flags})" if flags else "")
    other = [
        ("AVX2", "yes" if avx2 else "no"),
        ("tofmat SDK", __version__),
        ("matplotlib", _version_of("matplotlib")),
    ]
    for sdk in sorted(build_dir.parent.glob("sdk-*/CMakeCache.txt")):  # pip's build of the extension
        sdk_cache = _cmake_cache(sdk.parent)
        sdk_type = sdk_cache.get("CMAKE_BUILD_TYPE", "")
        sdk_flags = sdk_cache.get(f"CMAKE_CXX_FLAGS_{sdk_type.upper()}", "") if sdk_type else ""
        other.append(("SDK extension build (the Python figures)", f"{sdk.parent}: {sdk_type} ({sdk_flags})"))
    commit = _git_commit()
    if commit:
        other.append(("checkout", f"{commit} (HEAD; uncommitted changes are not shown)"))
    return Machine(
        date=datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
        cpu=cpu,
        cores=cores,
        os=_os(),
        compiler=compiler,
        cpp_build=cpp_build,
        python=f"{platform.python_implementation()} {platform.python_version()} ({sys.executable})",
        numpy=np.__version__,
        other=other,
    )


def cmake_cache_value(build_dir: Path, key: str) -> str:
    """A value of ``build_dir``'s CMakeCache.txt ("" when missing)."""
    return _cmake_cache(build_dir).get(key, "")


__all__ = ["Machine", "cmake_cache_value", "describe_machine"]
