#!/usr/bin/env bash
# Measures gearpulsed on the demo drive through the real chain (scripts/lib/harness.sh, 48 kHz capture):
# peak and current resident memory, CPU of the whole daemon (utime + stime of all threads over its
# wall time), time from GPS loss to engine-derived speed, and the pulse-count error over the drive.
#   bash scripts/measure_daemon.sh [BUILD_DIR] [gearpulse-devtools simulate options for the drive]
# Defaults: build/ and the demo drive (seed 1, 190 s, GPS outage 90:60). Prints the figures only.
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build}
shift || true
drive=("$@")
[ ${#drive[@]} -gt 0 ] || drive=(--seed 1 --duration 190 --outage 90:60)
outage=90:60
for ((i = 0; i < ${#drive[@]}; i++)); do
  [ "${drive[$i]}" = --outage ] && outage=${drive[$((i + 1))]}
done

# shellcheck source=scripts/lib/harness.sh
source scripts/lib/harness.sh
work=$(mktemp -d /tmp/gearpulse-measure.XXXXXX)
cleanup() {
  trap - EXIT INT TERM
  hs_stop 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT
trap 'cleanup; exit 130' INT TERM
hs_init "$work" "$build"
hs_prepare "${drive[@]}" >/dev/null
echo "drive: $(cat "$work/drive.log")"
hs_start
echo "capture: ALSA file plugin, $GEARPULSE_RATE Hz S16 mono, period $GEARPULSE_PERIOD frames; gpsd via gpsfake; PTY output"
/usr/bin/python3 scripts/lib/monitor.py --quiet --work "$work" --ctl "$GEARPULSE_CTL" --ppk "$GEARPULSE_PPK" \
  --outage "$outage" --poll 0.1 --until-pid "$(hs_pid feeder)"
hs_resources
