#!/usr/bin/env bash
# The one test command: installs what is missing, checks formatting, builds with warnings as errors, runs
# every test and the benches' accuracy checks, then every test again under AddressSanitizer+
# UndefinedBehaviorSanitizer, and the threaded parts (the ring, the newest-value snapshot, capture, gpsd
# client, pulse thread, log queue, control server, persistence, the in-process pipeline, its fault notes
# and the daemon's process) under ThreadSanitizer. Exit status is non-zero if anything fails, and if a
# test skipped that must run here: every test that needs the real logs (../shared/data/real) or a program
# setup.sh installs runs; only the skips listed in may_skip below are allowed. docs/testing.md says what
# each stage runs and how long it takes.
set -euo pipefail
cd "$(dirname "$0")/.."
jobs=$(nproc 2>/dev/null || echo 2)
logs=$(mktemp -d)
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$logs"' EXIT
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
export TSAN_OPTIONS=halt_on_error=1

bash scripts/setup.sh

# ccache when installed (setup.sh installs it): a run after a small change recompiles only what changed.
# Paths are hashed relative to the checkout (and the working directory not at all), so a clone at another
# path hits what a run in this one compiled; the precompiled header needs the two sloppiness settings.
launcher=()
if command -v ccache >/dev/null 2>&1; then
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  export CCACHE_BASEDIR=$PWD CCACHE_NOHASHDIR=true
  export CCACHE_SLOPPINESS=pch_defines,time_macros,include_file_mtime,include_file_ctime
fi
# Each stage's wall time, printed as it ends.
stage_start=$SECONDS
stage() {
  echo "== ($((SECONDS - stage_start)) s) $*"
  stage_start=$SECONDS
}

# Tests that may skip on this machine (ctest names, an extended regex): the GPIO tests without a GPIO chip,
# and the tests that need root when not run as root (locked memory, a tmpfs mounted, a gearpulsed that user
# nobody may run, systemd booted in a namespace of its own).
may_skip='^$'
if ! compgen -G '/dev/gpiochip*' >/dev/null; then may_skip+='|^gpio: '; fi
if [ "$(id -u)" -ne 0 ]; then
  may_skip+='|^realtime: locked memory|^daemon: a state_dir without room|^daemon: a state directory it may not'
  may_skip+='|^systemd unit: under systemd in a namespace'
fi
# Under the sanitizers: locking memory (their shadow mappings make it meaningless), running out of file
# descriptors (AddressSanitizer's runtime needs them), and the unit under systemd (its sandbox is checked on
# the release binary).
may_skip_sanitized="$may_skip|^realtime: locked memory|^control: out of file descriptors"
may_skip_sanitized+="|^systemd unit: under systemd in a namespace"

# Fails unless every test ctest reported skipped in log $1 matches the extended regex $2.
require_ran() {
  local bad
  bad=$(sed -n 's/^[[:space:]]*[0-9]* - \(.*\) (Skipped)$/\1/p' "$1" | grep -Ev "$2" || true)
  if [ -n "$bad" ]; then
    printf '== FAILED: these tests skipped and must run here:\n%s\n' "$bad" >&2
    exit 1
  fi
}

# The paced tests (ctest label "paced": the end-to-end drive, the pipeline's, the long run) spend minutes
# waiting on audio and fixes paced in real time and use a few percent of a core. They run all at once
# beside the work that needs the cores (the other tests, the sanitizer builds), which runs at the lowest CPU
# priority so that a paced test is served as soon as its audio or fix arrives (run at the same priority,
# a sanitized pipeline test once missed its outage's first seconds).
# Four at once in the release tree; two in the sanitizer trees, whose paced tests need several times the
# CPU (at four, a sanitized pipeline test twice missed a 20 s deadline for its first fix).
paced_jobs=4
paced_jobs_sanitized=2
busy=(nice -n 19)

# start_tests NAME DIR JOBS [ctest arguments] starts ctest on build tree DIR with JOBS tests at once (its
# output in $logs/NAME.log), at the lowest CPU priority unless NAME ends in "-paced" (below); finish_tests
# NAME MAY_SKIP waits for it, prints its output and fails on a failed test or a skip MAY_SKIP does not allow.
declare -A running
start_tests() {
  local name=$1 dir=$2 parallel=$3 runner=()
  shift 3
  if [[ $name != *-paced ]]; then runner=("${busy[@]}"); fi
  "${runner[@]}" ctest --test-dir "$dir" --output-on-failure --no-tests=error -j"$parallel" "$@" \
    >"$logs/$name.log" 2>&1 &
  running[$name]=$!
}
finish_tests() {
  local status=0
  wait "${running[$1]}" || status=$?
  cat "$logs/$1.log"
  if [ "$status" -ne 0 ]; then
    echo "== FAILED: the $1 tests" >&2
    exit 1
  fi
  require_ran "$logs/$1.log" "$2"
}

git ls-files '*.cpp' '*.hpp' | xargs -r clang-format --dry-run --Werror
stage "format check done"

# -O2 as a release, line tables only (-g1): a quarter less compile time than -g, the same warnings.
# The package's prefix (/usr) from the start, so that the package test's build changes nothing the tests run.
cmake -S . -B build -DGEARPULSE_WERROR=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_INSTALL_PREFIX=/usr \
  "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O2 -g1 -DNDEBUG" "${launcher[@]}" >/dev/null
cmake --build build -j"$jobs"
stage "release build done"
start_tests release-paced build "$paced_jobs" -L paced
start_tests release build "$jobs" -LE paced
finish_tests release "$may_skip"
stage "release tests but the paced ones (and the benches' checks) passed"

# The sanitizer trees skip the benchmarks (built with -Werror and run above). -O1 and line tables only (-g1,
# enough for the sanitizers' file:line reports) build in about half the time of -O2 -g; the tests and the
# programs' front ends compile at -O0 there (CMakeLists.txt). Built while the release tree's paced tests run.
cmake -S . -B build-asan -DGEARPULSE_WERROR=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG" \
  -DGEARPULSE_SANITIZE=address,undefined -DGEARPULSE_BENCH=OFF "${launcher[@]}" >/dev/null
"${busy[@]}" cmake --build build-asan -j"$jobs"
stage "ASan+UBSan build done"
# ThreadSanitizer: the files of the threaded parts (ctest lists only the cases of the executables built,
# so the names' prefixes select exactly them).
cmake -S . -B build-tsan -DGEARPULSE_WERROR=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG" -DGEARPULSE_SANITIZE=thread -DGEARPULSE_BENCH=OFF \
  "${launcher[@]}" >/dev/null
"${busy[@]}" cmake --build build-tsan -j"$jobs" --target spsc_ring_test published_test alsa_capture_test \
  alsa_recovery_test gpsd_client_test gpsd_backoff_test gps_history_test pulse_thread_test wake_event_test \
  log_queue_test control_test control_slots_test persistence_test training_store_test retrainer_test \
  pipeline_test pipeline_wake_test fault_reporter_test audio_front_end_test gearpulsed gearpulsectl \
  daemon_run_test daemon_state_test gearpulsectl_test state_saver_test
stage "TSan build done"
finish_tests release-paced "$may_skip"
stage "release tree's paced tests passed"

# The Debian package: built, installed, checked and purged (tests/ cannot run dpkg beside the other tests).
bash scripts/test_package.sh build | tee "$logs/package.log"
if grep -q GEARPULSE_SKIP "$logs/package.log"; then
  echo "== FAILED: the package test skipped and must run here" >&2
  exit 1
fi
stage "package installed, verified and purged"

# The three-minute drive in real time runs in the release tree only: under the sanitizers its daemon runs
# the same code the pipeline and daemon tests drive through the same ALSA, gpsd and PTY paths.
tsan_tests="^(ring|published|alsa|audio|gpsd|gps history|pulse|wake event|log queue|control|daemon|pipeline|faults|state saver):"
start_tests asan-paced build-asan "$paced_jobs_sanitized" -L paced -E "^e2e: (pulses match|10 Hz GPS)"
start_tests asan build-asan "$jobs" -LE paced
finish_tests asan "$may_skip_sanitized"
finish_tests asan-paced "$may_skip_sanitized"
stage "ASan+UBSan tests passed"
start_tests tsan-paced build-tsan "$paced_jobs_sanitized" -L paced -R "$tsan_tests"
start_tests tsan build-tsan "$jobs" -LE paced -R "$tsan_tests"
finish_tests tsan "$may_skip_sanitized"
finish_tests tsan-paced "$may_skip_sanitized"
stage "TSan tests passed"
echo "== all tests passed in $SECONDS s"
