#!/usr/bin/env bash
# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
# mk/apt-missing.sh PACKAGE...: prints those of the Debian packages that are not installed.
# A name without an architecture means the machine's own one (or an architecture-independent package):
# once arm64 is added for the cross build, `dpkg -s libgtest-dev` fails as ambiguous when both are installed,
# which made every `make setup` after the cross set-up run apt-get again.
set -u
native=$(dpkg --print-architecture)
installed() {
  dpkg-query -W -f='${db:Status-Abbrev}' "$1" 2>/dev/null | grep -q '^ii'
}
for p in "$@"; do
  case "$p" in
    *:*) installed "$p" || echo "$p" ;;
    *) installed "$p:$native" || installed "$p:all" || echo "$p" ;;
  esac
done
