#!/bin/sh
# The service unit under a real systemd: systemd boots as PID 1 of a new PID and mount namespace that
# holds only the gearpulsed unit (the targets it names, empty, beside it), runs the built daemon where the
# unit says, and the unit's behaviour is checked with systemctl:
#   started      Type=notify: active (running) once READY=1 came, as user gearpulse, with a status text
#   kill-9       a killed daemon is restarted (Restart=on-failure, RestartSec)
#   watchdog     a daemon that stops (SIGSTOP) is killed by the watchdog and restarted
#   reload       systemctl reload keeps the same process (ExecReload= sends SIGHUP)
#   stop         systemctl stop ends it with status 0
#   bad-config   a refused config fails the start with status 2, and no restart follows
# Usage: systemd_namespace.sh UNIT DAEMON SYSUSERS_CONF
#   UNIT: the unit as installed (the build's systemd/gearpulsed.service); DAEMON: the built gearpulsed.
# Prints "check NAME: ok" or "check NAME: FAILED (...)" for each, and exits 1 if any failed; prints
# GEARPULSE_SKIP and exits 0 when it cannot run (not root, no unshare, no systemd).
# Inside the namespace everything the unit writes goes to tmpfs: /run, /tmp, /var/tmp, /var/lib, a copy
# of /etc, the daemon's and the config's directories. systemd makes its cgroups in the host's hierarchy.
# shellcheck disable=SC2317 # the checks' functions are called through check() and the trap
set -u

if [ "${1:-}" = "--inside" ]; then
  # PID 1's shell, in the new namespaces: set the file system up, then become systemd.
  work=$2 daemon_path=$3 config_path=$4
  set -e
  mount -t tmpfs tmpfs /run
  mkdir -p /run/work
  cp -a "$work/." /run/work/
  mount -t tmpfs tmpfs /tmp
  mount -t tmpfs tmpfs /var/tmp
  mount -t tmpfs tmpfs /var/lib
  mkdir -p /run/shadow/etc /run/empty
  cp -a /etc/. /run/shadow/etc/
  mount --bind /run/shadow/etc /etc
  mount --bind /run/empty /etc/systemd/system
  mount --bind /run/work/units /lib/systemd/system
  # A directory for `path`, on tmpfs: made under the copy of /etc, or over its nearest existing parent.
  tmpdir_for() {
    dir=$1 parent=$1
    while [ ! -d "$parent" ]; do parent=$(dirname "$parent"); done
    case "$parent" in
      /etc | /etc/*) ;;
      *) mount -t tmpfs tmpfs "$parent" ;;
    esac
    mkdir -p "$dir"
  }
  tmpdir_for "$(dirname "$daemon_path")"
  cp /run/work/gearpulsed "$daemon_path"
  tmpdir_for "$(dirname "$config_path")"
  cp /run/work/gearpulse.toml "$config_path"
  systemd-sysusers /run/work/sysusers.conf
  exec /lib/systemd/systemd --system --unit=gearpulse-check.target --log-level=warning
fi

unit=$1 daemon=$2 sysusers=$3
skip() {
  echo "GEARPULSE_SKIP: $*"
  exit 0
}
[ "$(id -u)" -eq 0 ] || skip "booting systemd in a namespace needs root"
for p in unshare nsenter systemctl systemd-sysusers /lib/systemd/systemd; do
  command -v "$p" >/dev/null 2>&1 || skip "$p is not installed"
done
unshare --pid --mount --fork --mount-proc true 2>/dev/null || skip "cannot make a PID and mount namespace"

daemon_path=$(sed -n 's/^ExecStart=\([^ ]*\) .*/\1/p' "$unit")
config_path=$(sed -n 's/^ExecStart=[^ ]* --config \([^ ]*\).*/\1/p' "$unit")
if [ -z "$daemon_path" ] || [ -z "$config_path" ]; then
  echo "check unit: FAILED (no ExecStart=DAEMON --config FILE in $unit)"
  exit 1
fi

work=$(mktemp -d)
sd=""
cleanup() {
  # systemd is PID 1 of its namespace: killing it ends every process in there.
  [ -n "$sd" ] && kill -KILL "$sd" 2>/dev/null
  wait 2>/dev/null
  rm -rf "$work"
}
trap cleanup EXIT
mkdir -p "$work/units"
# A name of its own: systemd makes the unit's cgroup in the host's hierarchy, where another run's may be.
name=gearpulsed-check-$$.service
cp "$unit" "$work/units/$name"
cp "$daemon" "$work/gearpulsed"
cp "$sysusers" "$work/sysusers.conf"
printf '[output]\nkind = "none"\n' >"$work/gearpulse.toml"
printf '[Unit]\nDescription=gearpulsed under test\nDefaultDependencies=no\nWants=%s\n' "$name" \
  >"$work/units/gearpulse-check.target"
for t in $(sed -n 's/^\(Wants\|After\|Requires\|Before\|WantedBy\)=//p' "$unit") sysinit.target basic.target \
  shutdown.target; do
  case "$t" in *.target) ;; *) continue ;; esac # others named only by Wants= and After= may be missing
  [ -e "$work/units/$t" ] || printf '[Unit]\nDescription=%s (empty here)\nDefaultDependencies=no\n' "$t" \
    >"$work/units/$t"
done
unshare --pid --mount --fork --mount-proc sh "$0" --inside "$work" "$daemon_path" "$config_path" \
  </dev/null >"$work/boot.log" 2>&1 &
outer=$!
for _ in $(seq 50); do
  sd=$(pgrep -P "$outer" 2>/dev/null | head -n 1)
  [ -n "$sd" ] && [ "$(cat "/proc/$sd/comm" 2>/dev/null)" = systemd ] && break
  sd=""
  sleep 0.1
done
[ -n "$sd" ] || {
  echo "check boot: FAILED (systemd did not start: $(cat "$work/boot.log"))"
  exit 1
}
inside() { nsenter -t "$sd" -m -p "$@"; }
prop() { inside systemctl show -p "$1" --value "$name" 2>/dev/null; }
state() { echo "$(prop ActiveState)/$(prop SubState) result=$(prop Result) restarts=$(prop NRestarts)" \
  "status=$(prop ExecMainStatus) pid=$(prop MainPID)"; }
# until SECONDS CONDITION...: polls every 0.2 s.
until_true() {
  n=$(($1 * 5))
  shift
  while [ "$n" -gt 0 ]; do
    "$@" && return 0
    n=$((n - 1))
    sleep 0.2
  done
  return 1
}
failed=0
check() {
  what=$1
  shift
  if "$@"; then echo "check $what: ok ($(state))"; else
    echo "check $what: FAILED ($(state))"
    failed=1
  fi
}
running() { [ "$(prop ActiveState)/$(prop SubState)" = active/running ]; }
restarts_are() { [ "$(prop NRestarts)" = "$1" ] && running; }

has_status_text() { [ -n "$(prop StatusText)" ]; }
started() {
  until_true 20 running || return 1
  [ "$(inside ps -o uid= -p "$(prop MainPID)" | tr -d ' ')" = "$(inside id -u gearpulse)" ] || return 1
  until_true 10 has_status_text
}
check started started

# The daemon's process; fails (never 0: a kill of 0 would reach this script's process group).
main_pid() {
  pid=$(prop MainPID)
  [ "${pid:-0}" -gt 0 ]
}
killed() {
  main_pid || return 1
  inside kill -KILL "$pid"
  until_true 10 restarts_are 1 && [ "$(prop MainPID)" != "$pid" ]
}
check kill-9 killed

watchdog() {
  main_pid || return 1
  inside kill -STOP "$pid"
  # WatchdogSec (10 s), SIGABRT to a stopped process and its kill, RestartSec (2 s).
  until_true 40 restarts_are 2 && [ "$(prop MainPID)" != "$pid" ]
}
check watchdog watchdog

reloaded() {
  main_pid || return 1
  inside systemctl reload "$name" && sleep 1 && running && [ "$(prop MainPID)" = "$pid" ]
}
check reload reloaded

stopped() {
  inside systemctl stop "$name"
  [ "$(prop ActiveState)" = inactive ] && [ "$(prop Result)" = success ] && [ "$(prop ExecMainStatus)" = 0 ]
}
check stop stopped

bad_config() {
  inside sh -c "printf '[model]\nretrain_interval = -5\n' > '$config_path'"
  inside systemctl start "$name" 2>/dev/null && return 1
  # Two RestartSec and more: a restart would have come by now.
  sleep 5
  [ "$(prop ActiveState)" = failed ] && [ "$(prop NRestarts)" = 0 ] && [ "$(prop ExecMainStatus)" = 2 ]
}
check bad-config bad_config

exit "$failed"
