#!/usr/bin/env bash
# Runs every program whose figures docs/results.md quotes, each output in its own file, so that the page
# can be checked or brought up to date figure by figure:
#   bash scripts/results.sh [OUT_DIR]     (default: results/ in the source tree; about an hour on 2 cores)
# Builds the release tree with the benches first. The daemon's figures (scripts/measure_daemon.sh) need
# the demo's components (ALSA file plugin, gpsfake) and root, as the demo does.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-results}
mkdir -p "$out"
cmake -S . -B build -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
cmake --build build -j"$(nproc 2>/dev/null || echo 2)"

run() { # run NAME COMMAND...: the command's output in OUT/NAME.txt
  local name=$1
  shift
  echo "== $name: $*"
  if "$@" >"$out/$name.txt" 2>&1; then
    echo "   ok ($out/$name.txt)"
  else
    echo "   FAILED (exit $?; $out/$name.txt)" >&2
  fi
}

run outage-report build/bench/bench_outage --set report --seeds 2 --random 7
run outage-tuning build/bench/bench_outage --set tuning --seeds 2 --random 7
run outage-report-gps10 build/bench/bench_outage --set report --sim-only --seeds 2 --random 7 --cadence 0 --gps-hz 10
run first-drive build/bench/bench_first_drive --report
run real-logs build/bench/bench_real_logs
for seed in 1 2 3; do
  run "synth-sim-$seed" build/bench/bench_synth_sim "$seed"
  run "synth-sim-$seed-random" build/bench/bench_synth_sim "$seed" --random 28
done
run fit-sim-1 build/bench/bench_fit_sim 1 100
run fit-sim-5 build/bench/bench_fit_sim 5 0
run fit-sim-random build/bench/bench_fit_sim 0 0 40
run fit-sim-conditions build/bench/bench_fit_sim 0 0 0 3
run fit-speed build/bench/bench_fit_speed
run tracker build/bench/bench_tracker
run tracker-scenes-report build/bench/bench_tracker --scenes report
run tracker-runup-report build/bench/bench_tracker --scenes runup-report
run tracker-runup-report-real-band build/bench/bench_tracker --scenes runup-report --band 30:200 --window 0.2
run tracker-no-third-report build/bench/bench_tracker --scenes no-third-report
run tracker-clips-report build/bench/bench_tracker --scenes report --clips 5
run tracker-scenes-report-20db build/bench/bench_tracker --scenes report --scene-snr 20
run tracker-scenes-report-30db build/bench/bench_tracker --scenes report --scene-snr 30
run pulse build/bench/bench_pulse
run daemon bash scripts/measure_daemon.sh
echo "== outputs in $out/"
