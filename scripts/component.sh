#!/bin/sh
# A component the test suite needs from Debian (a broker, a browser, a codec): there already, else installed
# with apt-get when run as root, else a note and its tests skip. Under CI (CI=true) a component that is still
# missing fails this step, as its tests fail the run: a green CI has run every test.
# usage: component.sh "WHAT SKIPS WITHOUT IT" "DEBIAN PACKAGES" BINARY...
what=$1
packages=$2
shift 2
have() {
  for b in "$@"; do
    command -v "$b" >/dev/null 2>&1 || test -x "/usr/sbin/$b" || return 1
  done
}
have "$@" && exit 0
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
  # shellcheck disable=SC2086  # the package list is words
  apt-get install -y -qq $packages >/dev/null 2>&1 ||
    { apt-get update -qq >/dev/null && apt-get install -y -qq $packages >/dev/null; }
fi
have "$@" && exit 0
if [ "$CI" = true ]; then
  echo "error: $* not found and not installable here (Debian: $packages); under CI=true the $what must run" >&2
  exit 1
fi
echo "note: $* not found (Debian: $packages; installed when run as root); the $what will be skipped"
