# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The box's Debian packages (make package), checked as an administrator would use them.

`make package-test` runs this file with TOFMAT_DEB_AMD64 and TOFMAT_DEB_ARM64 naming the two
packages. It checks both with lintian, compares the arm64 package with the amd64 one, and walks the
amd64 package through install, start (the simulated camera, then the camera it is configured for),
status, upgrade, removal and purge in a scratch Debian root made with debootstrap, never on this
machine's own /. The root is thrown away at the end. Needs root (chroot, mount) and Debian's
package mirror; without either it fails, it never skips.
"""

from __future__ import annotations

import gzip
import io
import os
import shutil
import signal
import subprocess
import tarfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

import tofmat

REPO = Path(__file__).resolve().parents[2]


def _deb(var: str) -> Path:
    return _env_file(var)


@pytest.fixture(scope="module")
def deb_amd64() -> Path:
    return _deb("TOFMAT_DEB_AMD64")


@pytest.fixture(scope="module")
def deb_arm64() -> Path:
    return _deb("TOFMAT_DEB_ARM64")


def run(*cmd: str | Path, check: bool = True, **kw: object) -> subprocess.CompletedProcess[str]:
    p = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, **kw)  # type: ignore[call-overload]
    if check and p.returncode != 0:
        raise AssertionError(f"{' '.join(map(str, cmd))} exited {p.returncode}:\n{p.stdout}\n{p.stderr}")
    return p  # type: ignore[no-any-return]


def control(deb: Path) -> dict[str, str]:
    fields: dict[str, str] = {}
    for line in run("dpkg-deb", "--field", deb).stdout.splitlines():
        if line and not line[0].isspace() and ":" in line:
            key, value = line.split(":", 1)
            fields[key] = value.strip()
    return fields


def contents(deb: Path) -> dict[str, str]:
    """path -> mode string of every entry of the package's data."""
    out = {}
    for line in run("dpkg-deb", "--contents", deb).stdout.splitlines():
        parts = line.split()
        out[parts[5].lstrip(".")] = parts[0]
    return out


# --- the packages themselves --------------------------------------------------------------------


@pytest.mark.parametrize("arch", ["amd64", "arm64"])
def test_lintian_finds_no_error(arch: str, deb_amd64: Path, deb_arm64: Path) -> None:
    deb = deb_amd64 if arch == "amd64" else deb_arm64
    p = run("lintian", "--no-tag-display-limit", "--fail-on", "error", deb, check=False)
    print(p.stdout)
    assert p.returncode == 0, p.stdout + p.stderr
    assert not [ln for ln in p.stdout.splitlines() if ln.startswith("E:")], p.stdout


def test_both_packages_hold_the_same_files_for_their_architecture(deb_amd64: Path, deb_arm64: Path) -> None:
    amd, arm = control(deb_amd64), control(deb_arm64)
    assert (amd["Package"], amd["Architecture"]) == ("tofmatd", "amd64")
    assert (arm["Package"], arm["Architecture"]) == ("tofmatd", "arm64")
    assert amd["Version"] == arm["Version"] == tofmat.__version__
    for fields in (amd, arm):
        depends = fields["Depends"]
        for library in ("libusb-1.0-0", "libspdlog1.10", "libc6", "adduser"):
            assert library in depends, depends
        assert "opencv" not in depends, depends  # (the box's smoothing is its own integer code)
    files = contents(deb_amd64)
    assert files.keys() == contents(deb_arm64).keys()
    for path in ("/usr/sbin/tofmatd", "/etc/tofmat/tofmatd.toml", "/lib/systemd/system/tofmatd.service",
                 "/lib/udev/rules.d/90-tofmat-kinect2.rules", "/usr/share/tofmat/tables/tanaka2017.tmx",
                 "/usr/share/tofmat/sim/devices/kinect2_tanaka2017.json", "/usr/share/man/man8/tofmatd.8.gz",
                 "/usr/share/man/man5/tofmatd.toml.5.gz", "/usr/share/doc/tofmatd/copyright"):  # fmt: skip
        assert path in files, path
    assert files["/usr/sbin/tofmatd"] == "-rwxr-xr-x"
    with tarfile.open(fileobj=_data_tar(deb_arm64)) as tar:
        member = tar.extractfile("./usr/sbin/tofmatd")
        assert member is not None
        elf = member.read(20)
    assert elf[:4] == b"\x7fELF" and int.from_bytes(elf[18:20], "little") == 183  # EM_AARCH64


def _data_tar(deb: Path) -> io.BytesIO:
    return io.BytesIO(subprocess.run(["dpkg-deb", "--fsys-tarfile", str(deb)], capture_output=True, check=True).stdout)


def test_the_service_is_sandboxed() -> None:
    unit = REPO / "firmware" / "daemon" / "systemd" / "tofmatd.service"
    p = run("systemd-analyze", "security", "--offline=true", "--no-pager", unit)
    print(p.stdout)
    exposure = float(p.stdout.strip().splitlines()[-1].split("level for tofmatd.service:")[1].split()[0])
    assert exposure <= 2.0, p.stdout  # systemd rates 0-2 "OK"; the unit is written to stay there
    text = unit.read_text()
    for setting in ("User=tofmat", "NoNewPrivileges=yes", "ProtectSystem=strict", "PrivateTmp=yes",
                    "CapabilityBoundingSet=\n", "DeviceAllow=char-usb_device rw", "RestrictAddressFamilies="):  # fmt: skip
        assert setting in text, setting


# --- the life of the amd64 package in a scratch root --------------------------------------------


@pytest.fixture(scope="module")
def scratch_root(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    if os.geteuid() != 0:
        pytest.fail("the scratch-root test needs root (debootstrap, chroot, mount)", pytrace=False)
    root = tmp_path_factory.mktemp("scratch") / "root"
    cache = os.environ.get("TOFMAT_DEBOOTSTRAP_TARBALL")
    if cache and Path(cache).is_file():  # a minbase root made earlier by `debootstrap --make-tarball`
        run("debootstrap", "--variant=minbase", f"--unpack-tarball={cache}", "bookworm", root, timeout=900)
    else:
        run("debootstrap", "--variant=minbase", "bookworm", root, timeout=900)
    run("mount", "-t", "proc", "proc", root / "proc")
    try:
        yield root
    finally:
        subprocess.run(["umount", "-l", str(root / "proc")], check=False)
        shutil.rmtree(root, ignore_errors=True)


def chroot(root: Path, *cmd: str, check: bool = True, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    env = {"PATH": "/usr/sbin:/usr/bin:/sbin:/bin", "DEBIAN_FRONTEND": "noninteractive", "LC_ALL": "C"}
    return run("chroot", root, *cmd, check=check, timeout=timeout, env=env)


def start_daemon(root: Path, *args: str) -> subprocess.Popen[bytes]:
    # What systemd does for the unit: /run/tofmat for the service's user, then the daemon as that user.
    chroot(root, "install", "-d", "-o", "tofmat", "-g", "tofmat", "-m", "0750", "/run/tofmat")
    cmd = ["chroot", str(root), "setpriv", "--reuid=tofmat", "--regid=tofmat", "--init-groups",
           "/usr/sbin/tofmatd", "--config", "/etc/tofmat/tofmatd.toml", *args]  # fmt: skip
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)


def stop_daemon(proc: subprocess.Popen[bytes]) -> str:
    proc.send_signal(signal.SIGTERM)
    out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0, out.decode()
    return out.decode()


def connect(root: Path, proc: subprocess.Popen[bytes]) -> tofmat.Client:
    deadline = time.monotonic() + 60
    while True:
        assert proc.poll() is None, proc.communicate()[0].decode()
        try:
            return tofmat.Client(root / "run" / "tofmat" / "tofmatd.sock")
        except tofmat.DaemonUnavailableError:
            assert time.monotonic() < deadline, "tofmatd did not listen within 60 s"
            time.sleep(0.2)


def test_install_start_status_upgrade_remove_purge(scratch_root: Path, deb_amd64: Path, tmp_path: Path) -> None:
    root = scratch_root
    shutil.copy2(deb_amd64, root / "tmp" / "tofmatd.deb")
    chroot(root, "apt-get", "update", "-qq")
    chroot(root, "apt-get", "install", "-y", "-qq", "--no-install-recommends", "/tmp/tofmatd.deb")

    # Installed: the user and group, the files, the configuration that names the camera.
    user = chroot(root, "getent", "passwd", "tofmat").stdout.split(":")
    assert user[5] == "/nonexistent" and user[6].strip() == "/usr/sbin/nologin"
    assert int(user[2]) < 1000  # a system user
    group = chroot(root, "getent", "group", "tofmat").stdout.split(":")
    assert group[2] == user[3]
    assert "tofmat" in chroot(root, "getent", "group", "plugdev").stdout
    config = (root / "etc" / "tofmat" / "tofmatd.toml").read_text()
    assert 'source = "kinect"' in config and "/usr/share/tofmat/tables/tanaka2017.tmx" in config
    with gzip.open(root / "usr/share/man/man8/tofmatd.8.gz", "rt") as page:
        assert ".TH TOFMATD 8" in page.read().upper()
    assert chroot(root, "tofmatd", "--version").stdout.strip() == f"tofmatd {tofmat.__version__}"

    # Started as the service runs it, on the simulated camera (the box's self-test): labels say so.
    proc = start_daemon(root, "--source", "sim:static,material=cork,realtime=0")
    try:
        sock = root / "run" / "tofmat" / "tofmatd.sock"
        with connect(root, proc) as c:
            s = c.status()
            assert s["simulated"] is True and s["device"]["state"] in ("opening", "streaming")
            assert s["table"]["path"] == "/usr/share/tofmat/tables/tanaka2017.tmx"
            label = next(iter(c.labels(timeout=60)))
            assert label.simulated
        st = sock.stat()
        assert oct(st.st_mode & 0o777) == "0o660" and str(st.st_gid) == group[2] and str(st.st_uid) == user[2]
    finally:
        log = stop_daemon(proc)
    assert "SIMULATED" in log

    # Started with its configuration alone: the camera, which is not there; it says so and waits.
    proc = start_daemon(root)
    try:
        with connect(root, proc) as c:
            deadline = time.monotonic() + 30
            while (s := c.status())["device"]["state"] != "disconnected":
                assert time.monotonic() < deadline, s
                time.sleep(0.2)
            assert s["simulated"] is False and s["source"].startswith("Kinect v2")
    finally:
        stop_daemon(proc)

    # Upgrade to a later version: the administrator's edit of the configuration stays.
    (root / "etc/tofmat/tofmatd.toml").write_text(config.replace('profile = "handheld"', 'profile = "sorting"'))
    newer = _repacked_with_version(deb_amd64, f"{tofmat.__version__}+upgrade1", tmp_path)
    shutil.copy2(newer, root / "tmp" / "tofmatd-new.deb")
    chroot(root, "apt-get", "install", "-y", "-qq", "-o", "Dpkg::Options::=--force-confdef", "-o",
           "Dpkg::Options::=--force-confold", "/tmp/tofmatd-new.deb")  # fmt: skip
    assert chroot(root, "dpkg-query", "-W", "-f=${Version}", "tofmatd").stdout == f"{tofmat.__version__}+upgrade1"
    assert 'profile = "sorting"' in (root / "etc/tofmat/tofmatd.toml").read_text()
    proc = start_daemon(root, "--source", "sim:static,material=cork,realtime=0")
    try:
        with connect(root, proc) as c:
            assert c.status()["profile"] == "sorting"
    finally:
        stop_daemon(proc)

    # Removed: the program goes, the configuration stays; purged: the configuration goes too.
    chroot(root, "apt-get", "remove", "-y", "-qq", "tofmatd")
    assert not (root / "usr/sbin/tofmatd").exists() and (root / "etc/tofmat/tofmatd.toml").exists()
    assert not (root / "usr/share/tofmat").exists()
    chroot(root, "apt-get", "purge", "-y", "-qq", "tofmatd")
    assert not (root / "etc/tofmat").exists()
    assert chroot(root, "dpkg-query", "-W", "tofmatd", check=False).returncode != 0


def _repacked_with_version(deb: Path, version: str, tmp: Path) -> Path:
    tree = tmp / "repack"
    run("dpkg-deb", "-R", deb, tree)
    control_file = tree / "DEBIAN" / "control"
    lines = [f"Version: {version}" if ln.startswith("Version:") else ln for ln in control_file.read_text().splitlines()]
    control_file.write_text("\n".join(lines) + "\n")
    out = tmp / f"tofmatd_{version}_amd64.deb"
    run("dpkg-deb", "--root-owner-group", "-b", tree, out)
    return out


def test_the_shipped_table_is_the_real_database() -> None:
    shipped = tofmat.ExemplarTable.load(str(_env_file("TOFMAT_PACKAGE_TABLE")))
    db = os.environ.get("TOFMAT_DB_DIR", str(REPO.parent / "shared" / "data" / "tanaka2017_kinect2_db"))
    real = tofmat.ExemplarTable.from_npy_dir(db)
    assert shipped.materials == real.materials and len(shipped.materials) == 29
    assert shipped.features.shape == real.features.shape
    both = ~np.isnan(real.features)
    assert (np.isnan(shipped.features) == ~both).all()
    assert np.abs(shipped.features[both] - real.features[both]).max() < 0.01  # the table's int16 steps


def _env_file(var: str) -> Path:
    value = os.environ.get(var)
    if not value or not Path(value).is_file():
        pytest.fail(f"{var} must name a file (make package-test sets it), got {value!r}", pytrace=False)
    return Path(value)
