#!/usr/bin/env bash
# Runs gearpulsed on a simulated drive through the real components: the ALSA `file` plugin reading a
# FIFO that `gearpulse feed` fills at real-time pace, a real gpsd started by gpsfake from the drive's
# NMEA log, and the PTY pulse output counted by a reader. Shared by scripts/demo.sh,
# scripts/measure_daemon.sh and the end-to-end test, so all three drive exactly the same chain.
#
# As a library: `source scripts/lib/harness.sh`, then the hs_* functions.
# As a command (the test uses this; every step keeps its state in the work directory):
#   harness.sh prepare WORK BUILD [gearpulse simulate options for the drive...]
#   harness.sh start WORK        feeder, gpsfake, gearpulsed, pulse reader, then the audio (WORK/drive.t0)
#   harness.sh status WORK       `gearpulsectl status --json`
#   harness.sh pulses WORK       bytes (= pulses) read from the PTY so far
#   harness.sh resources WORK    gearpulsed's peak/current RSS and CPU share so far
#   harness.sh kill-daemon WORK  SIGKILL to gearpulsed (power cut)
#   harness.sh restart WORK      gearpulsed again (with a fresh feeder and reader; see hs_restart)
#   harness.sh stop WORK         stops everything it started
# Settings (environment, read by prepare): GEARPULSE_RATE (48000), GEARPULSE_PERIOD (1024 frames),
# GEARPULSE_PPK (2485), GEARPULSE_TRAIN_SEED (11), GEARPULSE_TRAIN_DURATION (2400 s), GEARPULSE_VEHICLE
# (bmw-520i), GEARPULSE_LOG_LEVEL (info), GEARPULSE_COLD (0; 1: no training drive, the daemon starts from
# an empty state directory), GEARPULSE_GPS_HZ (1: fix sets a second in the drive's NMEA log, 1, 2, 5 or 10;
# start plays the log at the rate its drive.env names), GEARPULSE_REALTIME (false: [audio] realtime,
# SCHED_FIFO threads and locked memory; true needs root or CAP_SYS_NICE and CAP_IPC_LOCK); read by start:
# GEARPULSE_GPS_ALIGN (0.9 s: the audio starts this long after gpsd reported the fix before the drive's
# t = 0, whose time WORK/drive.t0 holds).

hs_die() {
  echo "harness: $*" >&2
  exit 1
}

# hs_init WORK [BUILD]: work directory (created) and the build directory holding the binaries.
hs_init() {
  GEARPULSE_WORK=$(realpath -m "$1")
  mkdir -p "$GEARPULSE_WORK/pids" "$GEARPULSE_WORK/state"
  if [ -n "${2:-}" ]; then
    GEARPULSE_BUILD=$(realpath "$2")
  elif [ -f "$GEARPULSE_WORK/harness.env" ]; then
    # shellcheck disable=SC1091
    source "$GEARPULSE_WORK/harness.env"
  else
    hs_die "$GEARPULSE_WORK: not prepared (run: harness.sh prepare WORK BUILD)"
  fi
  GEARPULSE_CLI="$GEARPULSE_BUILD/tools/gearpulse"
  GEARPULSE_DEVTOOLS="$GEARPULSE_BUILD/tools/gearpulse-devtools"
  GEARPULSE_CTL="$GEARPULSE_BUILD/tools/gearpulsectl"
  GEARPULSE_DAEMON="$GEARPULSE_BUILD/daemon/gearpulsed"
  GEARPULSE_SOCKET="$GEARPULSE_WORK/control.sock"
  GEARPULSE_PTY="$GEARPULSE_WORK/pulse"
  GEARPULSE_CONFIG="$GEARPULSE_WORK/gearpulsed.toml"
}

hs_save_env() {
  {
    echo "GEARPULSE_BUILD='$GEARPULSE_BUILD'"
    echo "GEARPULSE_RATE='$GEARPULSE_RATE'"
    echo "GEARPULSE_PERIOD='$GEARPULSE_PERIOD'"
    echo "GEARPULSE_PPK='$GEARPULSE_PPK'"
    echo "GEARPULSE_PORT='${GEARPULSE_PORT:-}'"
    echo "GEARPULSE_LOG_LEVEL='$GEARPULSE_LOG_LEVEL'"
    echo "GEARPULSE_REALTIME='$GEARPULSE_REALTIME'"
  } >"$GEARPULSE_WORK/harness.env"
}

hs_defaults() {
  GEARPULSE_RATE=${GEARPULSE_RATE:-48000}
  GEARPULSE_PERIOD=${GEARPULSE_PERIOD:-1024}
  GEARPULSE_PPK=${GEARPULSE_PPK:-2485}
  GEARPULSE_TRAIN_SEED=${GEARPULSE_TRAIN_SEED:-11}
  GEARPULSE_TRAIN_DURATION=${GEARPULSE_TRAIN_DURATION:-2400}
  GEARPULSE_VEHICLE=${GEARPULSE_VEHICLE:-bmw-520i}
  GEARPULSE_LOG_LEVEL=${GEARPULSE_LOG_LEVEL:-info}
  GEARPULSE_REALTIME=${GEARPULSE_REALTIME:-false}  # [audio] realtime: SCHED_FIFO threads and locked memory
}

hs_check_tools() {
  local b
  for b in "$GEARPULSE_CLI" "$GEARPULSE_DEVTOOLS" "$GEARPULSE_CTL" "$GEARPULSE_DAEMON"; do
    [ -x "$b" ] || hs_die "$b is missing: build first (cmake --build build)"
  done
  command -v gpsfake >/dev/null || PATH=/usr/bin:$PATH command -v gpsfake >/dev/null ||
    hs_die "gpsfake is not installed (apt-get install gpsd gpsd-clients python3-gps)"
}

# A TCP port nobody has bound now, drawn below the kernel's ephemeral range (as tests/test_util.hpp's
# free_port: a port bind(0) hands out is also any connect's source port, and gpsd binds this one later).
hs_free_port() {
  /usr/bin/python3 -c '
import random, socket
low = int(open("/proc/sys/net/ipv4/ip_local_port_range").read().split()[0])
for _ in range(200):
    port = random.randint(10000, max(11000, low) - 1)
    s = socket.socket()
    try:
        s.bind(("127.0.0.1", port))
    except OSError:
        continue
    finally:
        s.close()
    print(port)
    break
else:
    raise SystemExit("no free port below the ephemeral range")'
}

# hs_prepare [simulate options...]: a training drive fitted offline into the state directory (the daemon
# loads state/model.json at start and keeps learning from then on), and the drive to replay.
hs_prepare() {
  hs_defaults
  hs_check_tools
  if [ "${GEARPULSE_COLD:-0}" = 1 ]; then
    echo "harness: no training drive: gearpulsed starts from an empty state directory"
  else
    echo "harness: training drive ($GEARPULSE_TRAIN_DURATION s of $GEARPULSE_VEHICLE, seed $GEARPULSE_TRAIN_SEED), fitted with gearpulse fit"
    "$GEARPULSE_DEVTOOLS" simulate --out "$GEARPULSE_WORK/train" --seed "$GEARPULSE_TRAIN_SEED" \
      --duration "$GEARPULSE_TRAIN_DURATION" --vehicle "$GEARPULSE_VEHICLE" --no-audio --pulses-per-km "$GEARPULSE_PPK" \
      >"$GEARPULSE_WORK/train.log" || hs_die "training drive failed: $(cat "$GEARPULSE_WORK/train.log")"
    "$GEARPULSE_CLI" fit --out "$GEARPULSE_WORK/state/model.json" "$GEARPULSE_WORK/train/samples.csv" \
      >"$GEARPULSE_WORK/fit.json" 2>"$GEARPULSE_WORK/fit.log" || hs_die "gearpulse fit failed: $(cat "$GEARPULSE_WORK/fit.log")"
  fi
  "$GEARPULSE_DEVTOOLS" simulate --out "$GEARPULSE_WORK/drive" --rate "$GEARPULSE_RATE" --vehicle "$GEARPULSE_VEHICLE" \
    --pulses-per-km "$GEARPULSE_PPK" ${GEARPULSE_GPS_HZ:+--gps-hz "$GEARPULSE_GPS_HZ"} "$@" \
    >"$GEARPULSE_WORK/drive.log" || hs_die "drive simulation failed"
  hs_save_env
}

# The ALSA configuration: PCM "replay" captures what the feeder writes into the FIFO.
hs_write_asound() {
  rm -f "$GEARPULSE_WORK/audio.fifo"
  mkfifo "$GEARPULSE_WORK/audio.fifo"
  cat >"$GEARPULSE_WORK/asound.conf" <<EOF
pcm.replay {
  type file
  slave.pcm null
  file "/dev/null"
  infile "$GEARPULSE_WORK/audio.fifo"
  format raw
}
EOF
}

hs_write_config() {
  cat >"$GEARPULSE_CONFIG" <<EOF
# Generated by scripts/lib/harness.sh for a simulated drive.
[audio]
device = "replay"
rate = $GEARPULSE_RATE
period_frames = $GEARPULSE_PERIOD
realtime = $GEARPULSE_REALTIME
[gps]
host = "127.0.0.1"
port = $GEARPULSE_PORT
[output]
kind = "pty"
path = "$GEARPULSE_PTY"
pulses_per_km = $GEARPULSE_PPK
[model]
state_dir = "$GEARPULSE_WORK/state"
[control]
socket = "$GEARPULSE_SOCKET"
[log]
level = "$GEARPULSE_LOG_LEVEL"
EOF
}

# hs_spawn NAME CMD...: starts CMD in the background, output to WORK/NAME.log, pid to WORK/pids/NAME.
hs_spawn() {
  local name=$1
  shift
  "$@" >>"$GEARPULSE_WORK/$name.log" 2>&1 </dev/null &
  echo $! >"$GEARPULSE_WORK/pids/$name"
}

hs_pid() { cat "$GEARPULSE_WORK/pids/$1" 2>/dev/null; }

hs_alive() {
  local pid
  pid=$(hs_pid "$1") && [ -n "$pid" ] && kill -0 "$pid" 2>/dev/null
}

# hs_start_feeder [feed options]: the drive's audio into the FIFO (--wait-start: from SIGUSR1 on).
# HS_FEEDER_FROM: the first line of WORK/feeder.log this feeder writes (a restart appends to it).
hs_start_feeder() {
  touch "$GEARPULSE_WORK/feeder.log"
  HS_FEEDER_FROM=$(($(wc -l <"$GEARPULSE_WORK/feeder.log") + 1))
  hs_spawn feeder "$GEARPULSE_DEVTOOLS" feed --period "$GEARPULSE_PERIOD" --rate "$GEARPULSE_RATE" --channels 1 --format s16 \
    "$@" "$GEARPULSE_WORK/drive/drive.raw" "$GEARPULSE_WORK/audio.fifo"
}

# gpsfake plays the log at once (-n); the log starts some seconds before the drive's t = 0, which is
# the epoch stamped 12:00:00 UTC (see gearpulse simulate --gps-lead). gpsfake finds gpsd's control
# socket by its own PID in $TMPDIR and takes a stale file of a killed run with the same PID for it (then
# gpsd gets no device): it keeps that socket in the run's directory. A log of N > 1 fix sets a second
# (drive.env's gps_hz) is played by scripts/lib/gps_player.py, gpsfake's machinery on a clock: `gpsfake -c`
# sleeps after each line, and its overhead per line (+8.5 % of the drive at 20 lines a second) would put
# the fixes seconds behind the audio by the drive's end. 1 Hz keeps gpsfake -c 0.5, whose pace every 1 Hz
# figure was measured with (+0.3 to 1 % behind, as the machine's load has it).
hs_start_gpsfake() {
  local hz
  GEARPULSE_PORT=$(hs_free_port)
  hs_save_env
  hz=$(sed -n 's/^gps_hz=//p' "$GEARPULSE_WORK/drive/drive.env")
  if [ "${hz:-1}" = 1 ]; then
    hs_spawn gpsfake env PATH="/usr/bin:$PATH" TMPDIR="$GEARPULSE_WORK" gpsfake -q -n -1 -P "$GEARPULSE_PORT" -c 0.5 "$GEARPULSE_WORK/drive/drive.nmea"
  else
    hs_spawn gpsfake env PATH="/usr/bin:$PATH" TMPDIR="$GEARPULSE_WORK" /usr/bin/python3 \
      "$(dirname "${BASH_SOURCE[0]}")/gps_player.py" "$GEARPULSE_WORK/drive/drive.nmea" "$GEARPULSE_PORT" $((2 * hz))
  fi
}

# hs_wait_gps_tpv FIRST LAST: blocks until gpsd reports a fix of 11:59:FIRST to 11:59:LAST (the drive's
# t = 0 is 12:00:00); sets HS_TPV_SECOND to the second of the fix it saw and HS_TPV_AT to the wall-clock
# time it saw it.
hs_wait_gps_tpv() {
  local t0 deadline seen="$GEARPULSE_WORK/tpv.seen" seconds match
  t0=$(date +%s)
  deadline=$((t0 + 30))
  seconds=$(seq -w -s '|' "$1" "$2")
  rm -f "$seen" "$seen.match"
  # gpsd may not listen yet: try again until the deadline. gpspipe ends by SIGPIPE once grep has its
  # line, at its next write, an epoch later: the time is taken as grep finds the line.
  until { timeout 10 env PATH="/usr/bin:$PATH" gpspipe -w "127.0.0.1:$GEARPULSE_PORT" 2>/dev/null || true; } |
    { grep -E -o -m1 "\"class\":\"TPV\".*\"time\":\"[0-9-]*T11:59:($seconds)" >"$seen.match" &&
      date +%s.%N >"$seen"; }; do
    [ "$(date +%s)" -lt "$deadline" ] ||
      hs_die "gpsd did not report the drive's first fixes within 30 s: $(tail -n 3 "$GEARPULSE_WORK/gpsfake.log")"
    hs_alive gpsfake || hs_die "gpsfake exited: $(tail -n 3 "$GEARPULSE_WORK/gpsfake.log")"
    sleep 0.2
  done
  HS_TPV_AT=$(cat "$seen")
  match=$(cat "$seen.match")
  HS_TPV_SECOND=$((10#${match: -2}))
  echo "harness: the fix of 11:59:${match: -2} after $(($(date +%s) - t0)) s" >>"$GEARPULSE_WORK/harness.log"
}

# hs_wait_feeder_open: blocks until the feeder started last says it has the FIFO open (the capture opened
# it) and waits for SIGUSR1 (gearpulse-devtools feed --wait-start); HS_FIFO_OPEN_AT: when it saw the line.
hs_wait_feeder_open() {
  local i
  for i in $(seq 200); do
    if tail -n +"$HS_FEEDER_FROM" "$GEARPULSE_WORK/feeder.log" | grep -q "FIFO open, waiting for SIGUSR1"; then
      HS_FIFO_OPEN_AT=$(date +%s.%N)
      return 0
    fi
    hs_alive feeder || hs_die "the feeder exited: $(tail -n 3 "$GEARPULSE_WORK/feeder.log")"
    sleep 0.05
  done
  hs_die "the FIFO was not opened within 10 s (gearpulsed's capture opens it): $(tail -n 3 "$GEARPULSE_WORK/gearpulsed.log")"
}

hs_signal_feeder() {
  kill -USR1 "$(hs_pid feeder)" || hs_die "the feeder is not running: $(tail -n 3 "$GEARPULSE_WORK/feeder.log")"
}

# hs_sleep_until AT: sleeps until the wall-clock time AT (s since the epoch); prints how late it is if AT
# has passed already (nothing otherwise).
hs_sleep_until() {
  awk -v a="$1" -v n="$(date +%s.%N)" 'BEGIN { if (n > a) printf "%.2f", n - a }'
  sleep "$(awk -v a="$1" -v n="$(date +%s.%N)" 'BEGIN { d = a - n; printf "%.6f", (d > 0 ? d : 0) }')"
}

# hs_start_audio AT: starts the drive's audio at the wall-clock time AT (the feeder waits for SIGUSR1
# with the FIFO open) and writes the time it did to WORK/drive.t0. A daemon ready after AT starts the
# audio late, which puts every fix that much earlier against the audio: said on stderr and in the log.
hs_start_audio() {
  local late
  hs_wait_feeder_open
  late=$(hs_sleep_until "$1")
  [ -z "$late" ] ||
    echo "harness: gearpulsed was ready $late s after the audio's start time: the audio starts late" |
    tee -a "$GEARPULSE_WORK/harness.log" >&2
  hs_signal_feeder
  date +%s.%N >"$GEARPULSE_WORK/drive.t0"
  echo "harness: the capture waited $(awk -v o="$HS_FIFO_OPEN_AT" -v t="$(cat "$GEARPULSE_WORK/drive.t0")" \
    'BEGIN { printf "%.2f", t - o }') s for the audio" >>"$GEARPULSE_WORK/harness.log"
}

hs_start_daemon() {
  hs_write_config
  "$GEARPULSE_DAEMON" --config "$GEARPULSE_CONFIG" --check-config >/dev/null || hs_die "generated config refused"
  hs_spawn gearpulsed env ALSA_CONFIG_PATH="/usr/share/alsa/alsa.conf:$GEARPULSE_WORK/asound.conf" \
    "$GEARPULSE_DAEMON" --config "$GEARPULSE_CONFIG"
}

# Counts pulses: one byte per pulse on the PTY, appended to WORK/pulses.bin (raw mode: no line
# discipline may eat or echo a byte).
hs_start_reader() {
  local i
  for i in $(seq 100); do
    [ -e "$GEARPULSE_PTY" ] && break
    hs_alive gearpulsed || hs_die "gearpulsed exited: $(tail -n 5 "$GEARPULSE_WORK/gearpulsed.log")"
    sleep 0.1
  done
  [ -e "$GEARPULSE_PTY" ] || hs_die "no PTY at $GEARPULSE_PTY after 10 s: $(tail -n 3 "$GEARPULSE_WORK/gearpulsed.log")"
  stty -F "$GEARPULSE_PTY" raw -echo 2>/dev/null || true
  touch "$GEARPULSE_WORK/pulses.bin"
  hs_spawn reader sh -c "exec cat \"$GEARPULSE_PTY\" >>\"$GEARPULSE_WORK/pulses.bin\""
}

hs_wait_socket() {
  local i
  for i in $(seq 100); do
    "$GEARPULSE_CTL" --socket "$GEARPULSE_SOCKET" status --json >/dev/null 2>&1 && return 0
    hs_alive gearpulsed || hs_die "gearpulsed exited: $(tail -n 5 "$GEARPULSE_WORK/gearpulsed.log")"
    sleep 0.1
  done
  hs_die "gearpulsed does not answer on $GEARPULSE_SOCKET"
}

# The audio starts GEARPULSE_GPS_ALIGN s after gpsd reported the fix of 11:59:59, reckoned from the first
# fix of 11:59 it reports and gpsfake's one-second epochs; the next fix is t = 0's: each fix then reaches the
# daemon 1 - GEARPULSE_GPS_ALIGN s after the audio of its moment, as a receiver's fix comes a little after
# its moment. gearpulsed starts daemon_lead before the audio: its start-up fits (it answered on its socket
# about 0.5 s after its start here), and its capture, open and waiting on the FIFO, gets the first period
# within its stall limit (2 s, kStallS in drivers/alsa_capture.cpp): no drive starts with the audio said
# stalled. Started with the audio instead, its start-up played into the FIFO unread and the audio reached
# it 1.5 s after its drive time for the whole drive (gearpulse-devtools feed).
hs_start() {
  local audio_at started late lead from
  local -r daemon_lead=1.2  # s
  hs_check_tools
  hs_write_asound
  hs_start_feeder --wait-start
  hs_start_gpsfake
  # gpsd reports the log's first fix (12:00:00 - gps_lead) at its first sentence too, half an epoch before
  # the rhythm of the rest (gpsfake -c 0.5, two sentences a fix): the fix after it is the first on time.
  lead=$(sed -n 's/^gps_lead_s=//p' "$GEARPULSE_WORK/drive/drive.env")
  from=$((61 - ${lead:-8}))
  hs_wait_gps_tpv "$((from < 0 ? 0 : from > 59 ? 59 : from))" 59
  audio_at=$(awk -v a="$HS_TPV_AT" -v s="$HS_TPV_SECOND" -v d="${GEARPULSE_GPS_ALIGN:-0.9}" \
    'BEGIN { printf "%.6f", a + 59 - s + d }')
  late=$(hs_sleep_until "$(awk -v a="$audio_at" -v l="$daemon_lead" 'BEGIN { printf "%.6f", a - l }')")
  [ -z "$late" ] || echo "harness: gearpulsed starts $late s late" >>"$GEARPULSE_WORK/harness.log"
  started=$(date +%s.%N)
  hs_start_daemon
  hs_start_reader
  hs_wait_socket
  echo "harness: gearpulsed answered $(awk -v s="$started" -v n="$(date +%s.%N)" 'BEGIN { printf "%.2f", n - s }') s after its start" >>"$GEARPULSE_WORK/harness.log"
  hs_start_audio "$audio_at"
}

# A second gearpulsed on the state the first left (after kill-daemon), with a fresh feeder and reader. The
# audio plays the drive again from its start once the daemon answers and its capture has the FIFO open,
# with no fixes aligned to it (gpsfake plays its log once). WORK/drive.t0 stays the first start's: the
# end-to-end test reads only the daemon's state after a restart.
hs_restart() {
  hs_stop_one reader
  hs_stop_one feeder
  hs_write_asound
  hs_start_feeder --wait-start
  hs_start_daemon
  hs_start_reader
  hs_wait_socket
  hs_wait_feeder_open
  hs_signal_feeder
}

# The daemon's resources so far: peak and current resident memory, CPU of all its threads over its life.
hs_resources() {
  local pid ticks start_ticks uptime utime stime hwm rss peak lck
  pid=$(hs_pid gearpulsed) || return 1
  ticks=$(getconf CLK_TCK)
  read -r utime stime start_ticks < <(awk '{print $14, $15, $22}' "/proc/$pid/stat")
  uptime=$(awk '{print $1}' /proc/uptime)
  hwm=$(awk '/^VmHWM/ {print $2}' "/proc/$pid/status")
  rss=$(awk '/^VmRSS/ {print $2}' "/proc/$pid/status")
  # Address space: what realtime memory locking counts against the unit's LimitMEMLOCK.
  peak=$(awk '/^VmPeak/ {print $2}' "/proc/$pid/status")
  lck=$(awk '/^VmLck/ {print $2}' "/proc/$pid/status")
  awk -v u="$utime" -v s="$stime" -v st="$start_ticks" -v up="$uptime" -v hz="$ticks" -v hwm="$hwm" \
    -v rss="$rss" -v peak="$peak" -v lck="$lck" -v rt="${GEARPULSE_REALTIME:-false}" 'BEGIN {
      wall = up - st / hz
      printf "gearpulsed: VmHWM %.1f MiB, VmRSS %.1f MiB, CPU %.2f %% of one core (user %.2f s + system %.2f s over %.0f s), VmPeak %.0f MiB, VmLck %.0f MiB (realtime = %s)\n",
        hwm / 1024, rss / 1024, 100 * (u + s) / hz / wall, u / hz, s / hz, wall, peak / 1024, lck / 1024, rt }'
}

hs_status() { "$GEARPULSE_CTL" --socket "$GEARPULSE_SOCKET" status --json; }

hs_pulses() { stat -c %s "$GEARPULSE_WORK/pulses.bin" 2>/dev/null || echo 0; }

# hs_stop_one NAME [SIGNAL]: signal, wait up to 5 s, then SIGKILL.
hs_stop_one() {
  local pid i
  pid=$(hs_pid "$1") || return 0
  [ -n "$pid" ] || return 0
  kill "-${2:-TERM}" "$pid" 2>/dev/null || true
  for i in $(seq 50); do
    kill -0 "$pid" 2>/dev/null || break
    sleep 0.1
  done
  kill -KILL "$pid" 2>/dev/null || true
  rm -f "$GEARPULSE_WORK/pids/$1"
}

hs_kill_daemon() {
  local pid
  pid=$(hs_pid gearpulsed) || hs_die "gearpulsed is not running"
  kill -KILL "$pid" 2>/dev/null || true
  while kill -0 "$pid" 2>/dev/null; do sleep 0.05; done
  rm -f "$GEARPULSE_WORK/pids/gearpulsed"
}

# Daemon first (SIGTERM: it saves the model and leaves the output low), then the sources and the reader.
# gpsd leaves behind the shared-memory segment it exports, keyed on its port as gpsfake sets it.
hs_stop() {
  hs_stop_one gearpulsed TERM
  hs_stop_one feeder
  hs_stop_one gpsfake
  if [ -n "${GEARPULSE_PORT:-}" ]; then
    ipcrm -M "$(printf '0x4770%04X' "$GEARPULSE_PORT")" 2>/dev/null || true
  fi
  hs_stop_one reader
}

if [[ "${BASH_SOURCE[0]}" == "$0" ]]; then
  set -euo pipefail
  cmd=${1:-}
  [ $# -ge 2 ] || hs_die "usage: harness.sh prepare|start|status|pulses|resources|kill-daemon|restart|stop WORK [...]"
  case "$cmd" in
    prepare)
      hs_init "$2" "${3:?harness.sh prepare WORK BUILD [simulate options]}"
      shift 3
      hs_prepare "$@"
      ;;
    start)
      hs_init "$2"
      # A half-started chain is stopped, not left running.
      trap 'rc=$?; if [ $rc -ne 0 ]; then hs_stop; fi; exit $rc' EXIT
      hs_start
      ;;
    status) hs_init "$2" && hs_status ;;
    pulses) hs_init "$2" && hs_pulses ;;
    resources) hs_init "$2" && hs_resources ;;
    kill-daemon) hs_init "$2" && hs_kill_daemon ;;
    restart)
      hs_init "$2"
      trap 'rc=$?; if [ $rc -ne 0 ]; then hs_stop; fi; exit $rc' EXIT
      hs_restart
      ;;
    stop) hs_init "$2" && hs_stop ;;
    *) hs_die "unknown command '$cmd'" ;;
  esac
fi
