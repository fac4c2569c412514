#!/usr/bin/env bash
# The gearpulse demo: gearpulsed runs on a simulated drive through the real components (ALSA capture via
# the file plugin reading a real-time FIFO, a real gpsd started by gpsfake, PTY pulse output) and shows
# `gearpulsectl status` as the drive goes: the speed source switches to `engine` during a 60 s GPS
# outage and back to `gps` after it. At the end: pulses counted on the PTY against the drive's true
# distance, and the time from GPS loss to engine-derived speed.
#
#   bash scripts/demo.sh [--duration SEC] [--outage START:LEN] [--seed N] [--fast] [--cold] [--keep] [--no-setup]
# Defaults are the real demo: a 5-minute drive (seed 1), GPS lost from 90 s to 150 s with a stop, moving
# off and five shifts inside, 48 kHz capture.
# --cold: no model fitted beforehand: gearpulsed starts from an empty state directory and the status lines
# show the model appear and grow (a 7-minute drive, GPS lost from 300 s to 360 s, unless given).
# The drive is generated deterministically at demo time (fixed seed): that is the bundled demo drive.
set -euo pipefail
cd "$(dirname "$0")/.."

duration=190
outage=90:60
seed=1
keep=0
setup=1
cold=0
duration_set=0
outage_set=0
while [ $# -gt 0 ]; do
  case "$1" in
    --duration) duration=$2; duration_set=1; shift 2 ;;
    --outage) outage=$2; outage_set=1; shift 2 ;;
    --cold) cold=1; shift ;;
    --seed) seed=$2; shift 2 ;;
    --fast) duration=130; outage=50:60; shift ;;
    --keep) keep=1; shift ;;
    --no-setup) setup=0; shift ;;
    -h | --help) sed -n '2,12p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "demo: unknown option '$1' (see --help)" >&2; exit 2 ;;
  esac
done
if [ "$cold" = 1 ]; then
  [ "$duration_set" = 1 ] || duration=420
  [ "$outage_set" = 1 ] || outage=300:60
fi

if [ "$setup" = 1 ]; then bash scripts/setup.sh; fi
echo "== build (Release, into build/)"
# Warnings stay warnings here (GCC 12 has -O3 false positives); scripts/test.sh builds with -Werror.
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DGEARPULSE_WERROR=OFF >/dev/null
cmake --build build -j"$(nproc 2>/dev/null || echo 2)" --target gearpulse gearpulse-devtools gearpulsectl gearpulsed >/dev/null

# shellcheck source=scripts/lib/harness.sh
source scripts/lib/harness.sh
work=$(mktemp -d /tmp/gearpulse-demo.XXXXXX)
cleanup() {
  trap - EXIT INT TERM
  hs_stop 2>/dev/null || true
  if [ "$keep" = 1 ]; then echo "demo: files kept in $work"; else rm -rf "$work"; fi
}
trap cleanup EXIT
trap 'echo; echo "demo: interrupted"; cleanup; exit 130' INT TERM
hs_init "$work" build

echo "== drive and model"
GEARPULSE_COLD=$cold hs_prepare --seed "$seed" --duration "$duration" --outage "$outage"
if [ "$cold" = 1 ]; then
  echo "   no model: the state directory ($work/state) is empty, as on a new install. gearpulsed learns"
  echo "   from GPS + engine pairs as it drives: a first model once one gear shows clearly, refits after"
  echo "   1, 2, 4, 8, 16 minutes of moving and whenever a gear it lacks shows (docs/cold-start.md)."
else
  echo "   model fitted offline into the state directory ($work/state/model.json):"
  /usr/bin/python3 -c 'import json,sys; m=json.load(open(sys.argv[1])); print("   thetas (m/s per Hz):", " ".join("%.4f" % g["theta"] for g in m["gears"]))' \
    "$work/state/model.json"
  echo "   gearpulsed loads it at start and keeps learning live from GPS + engine pairs (retrained periodically)."
fi
echo "   $(cat "$work/drive.log")"

echo "== run: feeder -> ALSA file plugin (PCM 'replay', 48 kHz) | gpsfake -> gpsd | gearpulsed -> PTY"
hs_start
echo "   gearpulsed pid $(hs_pid gearpulsed), gpsd port $GEARPULSE_PORT, pulses on $GEARPULSE_PTY, socket $GEARPULSE_SOCKET"
if [ "$cold" = 1 ]; then
  echo "   gearpulsectl status, every 3 s and at every change of source or model:"
  /usr/bin/python3 scripts/lib/monitor.py --work "$work" --ctl "$GEARPULSE_CTL" --ppk "$GEARPULSE_PPK" --outage "$outage" \
    --until-pid "$(hs_pid feeder)" --model
else
  echo "   gearpulsectl status, every 3 s and at every change of source:"
  /usr/bin/python3 scripts/lib/monitor.py --work "$work" --ctl "$GEARPULSE_CTL" --ppk "$GEARPULSE_PPK" --outage "$outage" \
    --until-pid "$(hs_pid feeder)"
fi
hs_resources
echo "== final gearpulsectl status"
"$GEARPULSE_CTL" --socket "$GEARPULSE_SOCKET" status || true
