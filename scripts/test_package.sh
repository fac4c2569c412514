#!/usr/bin/env bash
# Builds the Debian package from an existing build directory, installs it with dpkg, checks what it
# installed (files, user, state directory, --check-config on the installed configuration, systemd-analyze
# verify on the installed unit, the man pages), then removes and purges it and checks nothing is left.
#   bash scripts/test_package.sh BUILD_DIR
# Needs root and dpkg; prints GEARPULSE_SKIP and exits 0 where it cannot run. The build directory is
# reconfigured with -DCMAKE_INSTALL_PREFIX=/usr (the package's prefix) and the installed targets built.
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:?usage: test_package.sh BUILD_DIR}
[ -f "$build/CMakeCache.txt" ] || { echo "test_package: $build is not a configured build directory" >&2; exit 2; }

skip() { echo "GEARPULSE_SKIP: test_package: $*"; exit 0; }
[ "$(id -u)" -eq 0 ] || skip "needs root (dpkg -i)"
command -v dpkg >/dev/null && command -v cpack >/dev/null || skip "needs dpkg and cpack"
command -v scdoc >/dev/null || skip "needs scdoc for the man pages (scripts/setup.sh installs it)"
if dpkg-query -W -f='${Status}' gearpulse 2>/dev/null | grep -q 'installed'; then
  skip "a gearpulse package is already installed here; not replacing it"
fi

failures=0
check() { # check DESCRIPTION COMMAND...
  local what=$1
  shift
  if "$@" >/dev/null 2>&1; then
    echo "  ok    $what"
  else
    echo "  FAIL  $what" >&2
    failures=$((failures + 1))
  fi
}
cleanup() { dpkg -P gearpulse >/dev/null 2>&1 || true; }

echo "== package: build"
cmake -S . -B "$build" -DCMAKE_INSTALL_PREFIX=/usr >/dev/null
cmake --build "$build" -j"$(nproc 2>/dev/null || echo 2)" --target gearpulsed gearpulse gearpulsectl gearpulse_man
version=$(sed -n 's/^set(CPACK_PACKAGE_VERSION "\(.*\)")$/\1/p' "$build/CPackConfig.cmake")
deb="$build/gearpulse_${version}_$(dpkg --print-architecture).deb"
rm -f "$deb"
(cd "$build" && cpack -G DEB >/dev/null)
[ -f "$deb" ] || { echo "test_package: cpack made no $deb" >&2; exit 1; }
echo "   $deb"
check "depends on the libraries dpkg-shlibdeps found (libc6, libasound2)" \
  sh -c "dpkg-deb -f '$deb' Depends | grep -q libc6 && dpkg-deb -f '$deb' Depends | grep -q libasound2"
check "conffile /etc/gearpulse/gearpulse.toml" \
  sh -c "dpkg-deb -e '$deb' '$build/package-control' && grep -qx /etc/gearpulse/gearpulse.toml '$build/package-control/conffiles'"
rm -rf "$build/package-control"
check "no development tool packaged" sh -c "! dpkg-deb -c '$deb' | grep -q devtools"

echo "== package: install"
trap cleanup EXIT
dpkg -i "$deb"
for f in /usr/sbin/gearpulsed /usr/bin/gearpulse /usr/bin/gearpulsectl /etc/gearpulse/gearpulse.toml \
  /usr/lib/systemd/system/gearpulsed.service /usr/lib/sysusers.d/gearpulse.conf \
  /usr/lib/tmpfiles.d/gearpulse.conf /usr/share/man/man8/gearpulsed.8.gz /usr/share/man/man1/gearpulse.1.gz \
  /usr/share/man/man1/gearpulsectl.1.gz /usr/share/man/man5/gearpulse.toml.5.gz; do
  check "installed $f" test -f "$f"
done
check "system user gearpulse (systemd-sysusers)" getent passwd gearpulse
check "state directory /var/lib/gearpulse owned by gearpulse (systemd-tmpfiles)" \
  sh -c '[ "$(stat -c %U /var/lib/gearpulse)" = gearpulse ]'
check "gearpulsed --version is the package's version" sh -c "[ \"\$(/usr/sbin/gearpulsed --version)\" = 'gearpulsed $version' ]"
check "the unit runs /usr/sbin/gearpulsed" grep -qx \
  'ExecStart=/usr/sbin/gearpulsed --config /etc/gearpulse/gearpulse.toml' /usr/lib/systemd/system/gearpulsed.service
check "gearpulsed --check-config --config /etc/gearpulse/gearpulse.toml" \
  /usr/sbin/gearpulsed --check-config --config /etc/gearpulse/gearpulse.toml
if command -v systemd-analyze >/dev/null; then
  check "systemd-analyze verify gearpulsed.service" systemd-analyze verify /usr/lib/systemd/system/gearpulsed.service
else
  echo "GEARPULSE_SKIP: systemd-analyze verify: systemd-analyze is not installed"
fi
check "man -w gearpulse.toml" sh -c '[ "$(man -w gearpulse.toml)" = /usr/share/man/man5/gearpulse.toml.5.gz ]'

echo "== package: remove and purge"
dpkg -r gearpulse
check "binaries gone after dpkg -r" sh -c '! [ -e /usr/sbin/gearpulsed ] && ! [ -e /usr/bin/gearpulse ]'
check "conffile kept after dpkg -r" test -f /etc/gearpulse/gearpulse.toml
dpkg -P gearpulse
trap - EXIT
check "package unknown to dpkg after dpkg -P" sh -c '! dpkg-query -W -f="\${Status}" gearpulse 2>/dev/null | grep -q installed'
for f in /etc/gearpulse /var/lib/gearpulse /usr/lib/systemd/system/gearpulsed.service /usr/share/man/man5/gearpulse.toml.5.gz \
  /usr/lib/sysusers.d/gearpulse.conf /usr/lib/tmpfiles.d/gearpulse.conf; do
  check "gone after dpkg -P: $f" test ! -e "$f"
done
check "no unit state left by deb-systemd-helper" \
  sh -c '! ls /var/lib/systemd/deb-systemd-helper-enabled /var/lib/systemd/deb-systemd-helper-masked 2>/dev/null | grep -q gearpulsed'
if [ "$failures" -ne 0 ]; then
  echo "== package: $failures check(s) failed" >&2
  exit 1
fi
echo "== package: all checks passed"
