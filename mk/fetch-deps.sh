#!/usr/bin/env bash
# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
# Fetches, into build/deps, what Debian 12 lacks for the learned classifiers
# (docs/learned-models.md; the facts are in ../shared/docs/onnxruntime.md),
# without touching the system's apt sources:
#   onnxruntime  the C API headers of Debian 13's libonnxruntime-dev (1.21: the
#                C API is append-only, so they drive a newer library), and the
#                shared library of PyPI's onnxruntime wheels for x86_64 and
#                aarch64 (Debian 12 has no onnxruntime package)
#   qemu10       qemu-aarch64 10.0 from bookworm-backports (statically linked):
#                qemu 7.2 crashes in onnxruntime's CPU detection
# Every download is pinned by version and SHA-256. Idempotent: a part already
# fetched is left as it is.
set -euo pipefail
cd "$(dirname "$0")/.."
DEPS=${DEPS:-build/deps}
PYTHON=${PYTHON:-python3}

ORT_HEADERS_DEB=libonnxruntime-dev=1.21.0+dfsg-1
ORT_HEADERS_SHA=14f7d959d5deacbcf1504830d4189f91fc67382b399ed9ae9d3aa9c4050ced08
ORT_VERSION=1.31.1
declare -A ORT_WHEEL_SHA=(
  [x86_64]=5752bd508126ae7c49894d3b9d2e83f0c3d487319246d04c444b393308d7ad7f
  [aarch64]=da05378364c44d4407e463982d2bf8d5e4cfea873283757e48beeb41df97b7f3
)
QEMU_DEB=qemu-user=1:10.0.2+ds-2+deb13u1~bpo12+1
QEMU_SHA=10a2dec99f2b2d0b1097ff0375aea35b89322d6631fc96700511b02e05bf6fef

die() { echo "fetch-deps: $*" >&2; exit 1; }

check_sha() {  # file sha
  local got
  got=$(sha256sum "$1" | cut -d' ' -f1)
  [ "$got" = "$2" ] || die "$1: SHA-256 $got, expected $2"
}

# apt-get download from a private sources list (Debian 13 and bookworm-backports
# on the mirror apt already uses), with private lists and cache.
apt_download() {  # package=version sha dest-dir
  local apt="$DEPS/apt" mirror
  mirror=$(grep -rhE '^(URIs:|deb )' /etc/apt/sources.list /etc/apt/sources.list.d/ 2>/dev/null |
           grep -oE 'https?://[^ ]+/debian/?' | head -n1)
  mirror=${mirror:-http://deb.debian.org/debian}
  mkdir -p "$apt/lists/partial" "$apt/cache/archives/partial"
  local opts=(-o "Dir::Etc::SourceList=$PWD/$apt/sources.list" -o Dir::Etc::SourceParts=/dev/null
              -o "Dir::State::Lists=$PWD/$apt/lists" -o "Dir::Cache=$PWD/$apt/cache" -o APT::Sandbox::User=root)
  if [ ! -f "$apt/sources.list" ] || [ -z "$(ls "$apt/lists" 2>/dev/null | grep -v partial)" ]; then
    printf 'deb %s trixie main\ndeb %s bookworm-backports main\n' "$mirror" "$mirror" > "$apt/sources.list"
    apt-get "${opts[@]}" update -qq || die "apt-get update of $apt/sources.list failed"
  fi
  (cd "$3" && apt-get "${opts[@]}" download -qq "$1") || die "could not download $1"
  local deb
  deb=$(ls "$3"/"${1%%=*}"_*.deb | head -n1)
  check_sha "$deb" "$2"
  echo "$deb"
}

fetch_onnxruntime() {
  local dest="$DEPS/onnxruntime" tmp
  if [ -f "$dest/include/onnxruntime_c_api.h" ] && [ -e "$dest/lib/x86_64/libonnxruntime.so.1" ] &&
     [ -e "$dest/lib/aarch64/libonnxruntime.so.1" ]; then
    return 0
  fi
  echo "fetch-deps: onnxruntime $ORT_VERSION (library) and 1.21 (C API headers) into $dest"
  tmp=$(mktemp -d)
  trap 'rm -rf "$tmp"' RETURN
  mkdir -p "$dest/include" "$dest/lib"
  local deb
  deb=$(apt_download "$ORT_HEADERS_DEB" "$ORT_HEADERS_SHA" "$tmp")
  dpkg-deb -x "$deb" "$tmp/h"
  cp "$tmp"/h/usr/include/onnxruntime/*.h "$dest/include/"
  for arch in x86_64 aarch64; do
    "$PYTHON" -m pip download -q --no-deps --only-binary=:all: --platform "manylinux_2_28_$arch" \
      --python-version 3.11 "onnxruntime==$ORT_VERSION" -d "$tmp/$arch" || die "could not download the onnxruntime wheel ($arch)"
    local whl
    whl=$(ls "$tmp/$arch"/onnxruntime-*.whl)
    check_sha "$whl" "${ORT_WHEEL_SHA[$arch]}"
    mkdir -p "$dest/lib/$arch"
    unzip -q -o -j "$whl" "onnxruntime/capi/libonnxruntime.so.$ORT_VERSION" -d "$dest/lib/$arch"
    ln -sfn "libonnxruntime.so.$ORT_VERSION" "$dest/lib/$arch/libonnxruntime.so.1"
  done
}

fetch_qemu10() {
  local dest="$DEPS/qemu10" tmp
  [ -x "$dest/qemu-aarch64" ] && return 0
  echo "fetch-deps: qemu-aarch64 10.0 into $dest"
  tmp=$(mktemp -d)
  trap 'rm -rf "$tmp"' RETURN
  local deb
  deb=$(apt_download "$QEMU_DEB" "$QEMU_SHA" "$tmp")
  dpkg-deb --fsys-tarfile "$deb" | tar -x -C "$tmp" ./usr/bin/qemu-aarch64
  mkdir -p "$dest"
  install -m 0755 "$tmp/usr/bin/qemu-aarch64" "$dest/qemu-aarch64"
}

[ $# -gt 0 ] || die "usage: $0 onnxruntime|qemu10 ..."
for part in "$@"; do
  case "$part" in
    onnxruntime) fetch_onnxruntime ;;
    qemu10) fetch_qemu10 ;;
    *) die "unknown part '$part' (onnxruntime, qemu10)" ;;
  esac
done
