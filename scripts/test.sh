#!/usr/bin/env bash
# The one test command: installs what is missing, builds with warnings as errors, runs every test,
# then again under AddressSanitizer+UndefinedBehaviorSanitizer, the threaded parts (the ring, capture,
# gpsd client, pulse thread, log queue, control server, persistence, the in-process pipeline and the
# daemon's process) under ThreadSanitizer, and checks formatting. Exit status is non-zero if anything fails.
set -euo pipefail
cd "$(dirname "$0")/.."
jobs=$(nproc 2>/dev/null || echo 2)

bash scripts/setup.sh

echo "== format check"
git ls-files '*.cpp' '*.hpp' | xargs -r clang-format --dry-run --Werror

echo "== release build + tests"
cmake -S . -B build -DGEARPULSE_WERROR=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
cmake --build build -j"$jobs"
ctest --test-dir build --output-on-failure -j"$jobs"
bash scripts/test_package.sh build

echo "== ASan+UBSan build + tests"
# The benchmarks are built (with -Werror) above and not run here: the sanitizer build skips them. -O1 and
# line tables only (-g1, enough for the sanitizers' file:line reports) build it in about 6 minutes on 2
# cores instead of about 11 with -O2 -g.
cmake -S . -B build-asan -DGEARPULSE_WERROR=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG" \
  -DGEARPULSE_SANITIZE=address,undefined -DGEARPULSE_BENCH=OFF >/dev/null
cmake --build build-asan -j"$jobs"
ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
  ctest --test-dir build-asan --output-on-failure -j"$jobs"

echo "== TSan: the threaded parts"
# Every test of these files (ctest lists only the cases of the executables built, so the names' prefixes
# select exactly them): about 2 minutes to build and 1.5 to run on 2 cores, -O1 as the ASan build.
cmake -S . -B build-tsan -DGEARPULSE_WERROR=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG" -DGEARPULSE_SANITIZE=thread -DGEARPULSE_BENCH=OFF >/dev/null
cmake --build build-tsan -j"$jobs" --target spsc_ring_test alsa_capture_test gpsd_client_test pulse_thread_test \
  log_queue_test control_test persistence_test pipeline_test gearpulsed gearpulsectl daemon_run_test
TSAN_OPTIONS=halt_on_error=1 ctest --test-dir build-tsan --output-on-failure -j"$jobs" \
  -R "^(ring|alsa|gpsd|pulse|log queue|control|daemon|pipeline):"
echo "== all tests passed"
