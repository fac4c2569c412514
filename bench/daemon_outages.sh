#!/usr/bin/env bash
# gearpulsed end to end on GPS outages that begin at a downshift under braking that skips a gear (4 -> 2,
# 5 -> 3): each drive is played through the real chain of scripts/lib/harness.sh (ALSA file plugin at
# 48 kHz, gpsd via gpsfake, PTY output), one at a time and at real-time pace (3-4 minutes a drive), with
# the model fitted offline from the harness' training drive. Per drive it prints `figure` lines: the
# daemon's outage distance error against the distance driven over its own outage (between the status
# polls where it lost GPS and had it back), `gearpulse replay`'s on the same audio and fixes over its
# own, their difference, and what the polls' spacing at the edges may add (bench/daemon_outage_figures.py).
#   bash bench/daemon_outages.sh [BUILD_DIR] [DRIVE...]
# DRIVE is STYLE:SEED:DURATION[:on] (`on`: a skip after which the car drives on in the lower gear, not one
# braking to a stop); the default is every drive below. Needs gpsfake (as scripts/demo.sh) and the
# built gearpulse, gearpulse-devtools, gearpulsectl and gearpulsed. GEARPULSE_KEEP=1 keeps the drives'
# directories (bench/daemon_outage_figures.py --offline recomputes a drive's figures from one).
#
# TUNING SET: mixed seeds 1-3 (skips braking to a stop) and highway seed 1 (braking,
# a skip 5 -> 3 at 40 km/h, then a minute in 3rd). Decide on these only.
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build}
shift || true
drives=("$@")
[ ${#drives[@]} -gt 0 ] || drives=(mixed:1:150 mixed:2:200 mixed:3:150 highway:1:150:on)
outage_len=60     # s of GPS outage from the skip
skip_share=1      # every braking downshift that can skip does (gearpulse-devtools simulate --skip-downshift)
# The audio starts GEARPULSE_GPS_ALIGN (the harness' 0.9 s) after gpsd reports the fix before the drive's
# t = 0: each fix reaches the daemon within 0.1 s of the audio of its moment, later by about 0.3 s per 100 s
# of drive (gpsfake's pace), as a receiver's fix comes at or after its moment.

# shellcheck source=scripts/lib/harness.sh
source scripts/lib/harness.sh
root=$(mktemp -d /tmp/gearpulse-outages.XXXXXX)
cleanup() {
  trap - EXIT INT TERM
  hs_stop 2>/dev/null || true
  [ "${GEARPULSE_KEEP:-0}" = 1 ] && echo "files kept in $root" || rm -rf "$root"
}
trap cleanup EXIT
trap 'cleanup; exit 130' INT TERM

for d in "${drives[@]}"; do
  IFS=: read -r style seed duration on <<<"$d"
  label="${style}_${seed}"
  opts=(--style "$style" --seed "$seed" --duration "$duration" --skip-downshift "$skip_share"
    --outage-at-skip "$outage_len")
  [ "${on:-}" = on ] && opts+=(--skip-drive-on)
  hs_init "$root/$label" "$build"
  hs_prepare "${opts[@]}" >/dev/null
  echo "drive $label: $(tr '\n' ' ' <"$GEARPULSE_WORK/drive.log")"
  # shellcheck disable=SC1091
  source "$GEARPULSE_WORK/drive/drive.env"
  hs_start
  /usr/bin/python3 bench/daemon_outage_figures.py --work "$GEARPULSE_WORK" --ctl "$GEARPULSE_CTL" \
    --cli "$GEARPULSE_CLI" --ppk "$GEARPULSE_PPK" --outage "$outage_start_s:$outage_length_s" \
    --until-pid "$(hs_pid feeder)" --label "$label"
  hs_stop
  grep -E 'speed source|retrain|model' "$GEARPULSE_WORK/gearpulsed.log" | sed 's/^/  log: /' | head -n 12 || true
done
