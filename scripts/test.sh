#!/usr/bin/env bash
# The whole test suite, as CI runs it (.ci/run calls exactly this):
#   1. scripts/setup.sh (packages; quick when already installed)
#   2. clang-format --dry-run --Werror over every tracked *.cpp/*.hpp
#   3. build/      RelWithDebInfo (line tables only), warnings are errors
#   4. build-server/, build-viewer/, build-builder/: the other configurations (server only, which
#                  the deploy test checks; viewer without the builder; builder without the
#                  renderer); with ccache (when installed) their objects come from build/'s
#   5. build/      every ctest (unit, fuzz-corpus replays, lint, integration)
#   6. build-asan/ ASan + UBSan: only the unit-test executables and fuzz replays (ctest -L unit)
#   7. build-tsan/ TSan: the unit tests of the multi-threaded libraries (server, client with the
#                  fetcher, loadtest)
# Keeps going after a failure so one run reports everything; exits non-zero if any step failed.
# Logs of every step are kept in build-logs/.
#
#   bash scripts/test.sh
#   VTS_TEST_SKIP_ASAN=1 VTS_TEST_SKIP_TSAN=1 bash scripts/test.sh   # without the sanitizer builds
set -uo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT" || exit 1

JOBS=${VTS_JOBS:-2}
LOGS="$ROOT/build-logs"
mkdir -p "$LOGS"
T0=$(date +%s)

STEP_RESULTS=()
FAILED=0
TESTS_PASSED=0
TESTS_FAILED=0

banner() { printf '\n==== %s ====\n' "$*"; }

record() { # NAME RESULT SECONDS [DETAIL]
  STEP_RESULTS+=("$(printf '%-5s %-34s %5ss  %s' "$2" "$1" "$3" "${4:-}")")
  [[ $2 == FAIL ]] && FAILED=1
  return 0
}

# step NAME CMD...: runs CMD, logging to build-logs/NAME.log; records PASS/FAIL. Returns CMD's rc.
step() {
  local name=$1 log start rc
  shift
  log="$LOGS/${name//[^A-Za-z0-9_.-]/_}.log"
  banner "$name"
  start=$(date +%s)
  "$@" 2>&1 | tee "$log"
  rc=${PIPESTATUS[0]}
  if ((rc == 0)); then
    record "$name" PASS $(($(date +%s) - start))
  else
    record "$name" FAIL $(($(date +%s) - start)) "exit $rc; log: ${log#"$ROOT"/}"
  fi
  return "$rc"
}

skip() { # NAME REASON
  banner "$1 (skipped: $2)"
  STEP_RESULTS+=("$(printf '%-5s %-34s %5s   %s' SKIP "$1" - "$2")")
}

# ctest_step NAME BUILD_DIR [CTEST ARGS...]: like step, and adds ctest's counts to the totals.
# ctest runs with the environment assignments in CTEST_ENV added.
CTEST_ENV=()
ctest_step() {
  local name=$1 dir=$2 log start rc line failed total
  shift 2
  log="$LOGS/${name//[^A-Za-z0-9_.-]/_}.log"
  banner "$name"
  start=$(date +%s)
  env "${CTEST_ENV[@]}" ctest --test-dir "$dir" --output-on-failure --no-tests=error -j"$JOBS" --timeout 900 "$@" 2>&1 |
    tee "$log"
  rc=${PIPESTATUS[0]}
  line=$(grep -E '^[0-9]+% tests passed, [0-9]+ tests? failed out of [0-9]+' "$log" | tail -n1)
  if [[ -n $line ]]; then
    failed=$(sed -E 's/.* ([0-9]+) tests? failed out of ([0-9]+).*/\1/' <<<"$line")
    total=$(sed -E 's/.* failed out of ([0-9]+).*/\1/' <<<"$line")
    TESTS_PASSED=$((TESTS_PASSED + total - failed))
    TESTS_FAILED=$((TESTS_FAILED + failed))
  fi
  local unit="tests"
  if [[ " $* " == *" -V "* ]]; then
    # Shards of GoogleTest executables (sanitizer builds): count the tests they ran, from
    # GoogleTest's own summaries ("[  PASSED  ] N tests.", "[  FAILED  ] N tests, listed below").
    local gpassed gfailed
    gpassed=$(grep -oE '\[  PASSED  \] [0-9]+ tests?\.' "$log" | awk '{s += $4} END {print s + 0}')
    gfailed=$(grep -oE '\[  FAILED  \] [0-9]+ tests?, listed below' "$log" | awk '{s += $4} END {print s + 0}')
    # A shard that crashed (a sanitizer report) prints no summary: count it as one failure.
    ((gfailed == 0 && failed > 0)) && gfailed=$failed
    TESTS_PASSED=$((TESTS_PASSED - (total - failed) + gpassed))
    TESTS_FAILED=$((TESTS_FAILED - failed + gfailed))
    unit="tests in $total shards"
    failed=$gfailed total=$((gpassed + gfailed))
    ((total > 0)) || rc=1  # shards that ran no test: a filter or registration gone wrong
  fi
  local secs=$(($(date +%s) - start))
  if ((rc == 0)); then
    record "$name" PASS "$secs" "${total:-?} $unit"
  else
    record "$name" FAIL "$secs" "${failed:-?} of ${total:-?} $unit failed; log: ${log#"$ROOT"/}"
  fi
  return "$rc"
}

# configure DIR CMAKE ARGS...: cmake -G Ninja, starting afresh if DIR was made by another generator.
# Every build is a unity build (CMake compiles each target's sources eight to a file): the
# headers every file includes (Boost.Beast, nlohmann/json, GoogleTest) are parsed and their
# templates instantiated once per eight files, which more than halves the compile time on two
# cores. VTS_UNITY_BUILD=OFF builds file by file.
# shellcheck disable=SC2317  # called through step()
configure() {
  local dir=$1
  shift
  if [[ -f $dir/CMakeCache.txt ]] && ! grep -q '^CMAKE_GENERATOR:INTERNAL=Ninja$' "$dir/CMakeCache.txt"; then
    echo "$dir was configured with another generator; reconfiguring from scratch"
    rm -rf "$dir/CMakeCache.txt" "$dir/CMakeFiles"
  fi
  cmake -S "$ROOT" -B "$dir" -G Ninja "${LAUNCHER[@]}" -DCMAKE_UNITY_BUILD="${VTS_UNITY_BUILD:-ON}" "$@"
}

# ccache, when installed, lets builds with the same flags share objects (build/ and build-server/).
LAUNCHER=()
if command -v ccache >/dev/null 2>&1; then
  # NOHASHDIR: with -g, ccache would otherwise key each object on its build folder.
  export CCACHE_BASEDIR="$ROOT" CCACHE_DIR="${CCACHE_DIR:-$ROOT/build-ccache}" CCACHE_NOHASHDIR=1
  LAUNCHER=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
fi

# --- 1. set-up -----------------------------------------------------------------------------------
step "setup" bash scripts/setup.sh

# --- 2. formatting ------------------------------------------------------------------------------
# shellcheck disable=SC2317  # called through step()
format_check() {
  git ls-files -z '*.cpp' '*.hpp' | xargs -0 clang-format --dry-run --Werror
}
if git rev-parse --git-dir >/dev/null 2>&1; then
  step "clang-format" format_check
else
  skip "clang-format" "not a git checkout"
fi

# Debug information: line tables only (-g1). Backtraces, ASan and TSan reports keep file:line, and
# compiling takes a quarter to a third less time than with -g (measured on the heaviest files).
RELWITHDEBINFO_FLAGS=(-DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O2 -g1 -DNDEBUG"
  -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O2 -g1 -DNDEBUG")

# --- 3. main build: everything ------------------------------------------------------------------
MAIN_BUILT=0
if step "configure build/" configure build -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  "${RELWITHDEBINFO_FLAGS[@]}" -DVTS_WERROR=ON -DVTS_BUILD_RENDERER="${VTS_BUILD_RENDERER:-ON}"; then
  step "build build/" cmake --build build -j"$JOBS" && MAIN_BUILT=1
else
  skip "build build/" "configure failed"
fi

# --- 4. the other configurations users build: each must configure and build ----------------------
# server-only: the deployment's `vts` (checked by the deploy test); viewer without the builder;
# builder without the renderer. The same flags as build/, so ccache serves every object they share
# with the main build and only what differs (the CLI's entry points) is compiled.
# config_build DIR TARGETS CMAKE ARGS...: configure DIR and build TARGETS (comma-separated).
# shellcheck disable=SC2317  # called through step()
config_build() {
  local dir=$1 targets=$2 t
  shift 2
  if step "configure $dir/" configure "$dir" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    "${RELWITHDEBINFO_FLAGS[@]}" -DVTS_BUILD_TESTS=OFF -DVTS_WERROR=ON "$@"; then
    local args=()
    for t in ${targets//,/ }; do args+=(--target "$t"); done
    step "build $dir/ ($targets)" cmake --build "$dir" -j"$JOBS" "${args[@]}"
  else
    skip "build $dir/ ($targets)" "configure failed"
    return 1
  fi
}
if config_build build-server vts -DVTS_BUILD_RENDERER=OFF -DVTS_BUILD_BUILDER=OFF -DVTS_BUILD_BENCH=OFF; then
  export VTS_SERVER_ONLY="$ROOT/build-server/cli/vts"
fi
config_build build-viewer vts -DVTS_BUILD_RENDERER=ON -DVTS_BUILD_BUILDER=OFF -DVTS_BUILD_BENCH=OFF
config_build build-builder vts,vts-build -DVTS_BUILD_RENDERER=OFF -DVTS_BUILD_BUILDER=ON

# --- 5. every test of the main build (the deploy test reads VTS_SERVER_ONLY) --------------------
if ((MAIN_BUILT)); then
  ctest_step "ctest build/" build
else
  skip "ctest build/" "build failed"
fi

# sanitizer_build NAME DIR GTEST_EXCLUDE [CMAKE ARGS...]: configures DIR, builds only
# `unit_tests` (the executables `ctest -L unit` runs) and runs ctest -L unit there, minus the
# GoogleTest tests matching the pattern GTEST_EXCLUDE ("" = none). There each executable runs as
# a few shards (tests/CMakeLists.txt); -V with GTEST_BRIEF keeps each shard's summary in the log.
sanitizer_build() {
  local name=$1 dir=$2 exclude=$3 ctest_args=(-L unit -V)
  shift 3
  if step "configure $dir/" configure "$dir" -DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_FLAGS=-O1 \
    -DCMAKE_CXX_FLAGS_DEBUG=-g1 -DCMAKE_C_FLAGS_DEBUG=-g1 \
    -DVTS_BUILD_RENDERER=OFF -DVTS_BUILD_BENCH=OFF "$@"; then
    if step "build $dir/ (unit_tests)" cmake --build "$dir" -j"$JOBS" --target unit_tests; then
      CTEST_ENV=(GTEST_BRIEF=1)
      [[ -n $exclude ]] && CTEST_ENV+=("GTEST_FILTER=-$exclude")
      ctest_step "ctest $dir/ -L unit ($name)" "$dir" "${ctest_args[@]}"
      CTEST_ENV=()
    else
      skip "ctest $dir/ -L unit ($name)" "build failed"
    fi
  else
    skip "build $dir/ (unit_tests)" "configure failed"
    skip "ctest $dir/ -L unit ($name)" "configure failed"
  fi
}

# --- 6. sanitizer build: unit tests under ASan + UBSan --------------------------------------------
if [[ ${VTS_TEST_SKIP_ASAN:-0} == 1 ]]; then
  skip "ASan+UBSan" "VTS_TEST_SKIP_ASAN=1"
else
  export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:check_initialization_order=1:strict_init_order=1:detect_stack_use_after_return=1}
  # Leaks inside third-party libraries only (each one named and explained in the file).
  export LSAN_OPTIONS=${LSAN_OPTIONS:-suppressions=$ROOT/tests/lsan.supp:print_suppressions=0}
  export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
  sanitizer_build "ASan+UBSan" build-asan "" -DVTS_SANITIZE=address
fi

# --- 7. sanitizer build: the multi-threaded libraries' unit tests under TSan ----------------------
if [[ ${VTS_TEST_SKIP_TSAN:-0} == 1 ]]; then
  skip "TSan" "VTS_TEST_SKIP_TSAN=1"
else
  export TSAN_OPTIONS=${TSAN_OPTIONS:-second_deadlock_stack=1:history_size=4}
  # Every test of those libraries: the load tests that assert rates and latencies run on a virtual
  # clock (LoadTestOptions::now / sleep_until), so TSan's slowdown does not change their figures.
  sanitizer_build "TSan" build-tsan "" -DVTS_SANITIZE=thread \
    "-DVTS_UNIT_TESTS=store;server;client;loadtest"
fi

# --- summary ---------------------------------------------------------------------------------------
banner "vtstream test summary ($(($(date +%s) - T0))s)"
printf '  %s\n' "${STEP_RESULTS[@]}"
if ((FAILED)); then
  echo "RESULT: FAILED"
else
  echo "RESULT: all steps passed"
fi
echo "tests: $TESTS_PASSED passed, $TESTS_FAILED failed"
exit "$FAILED"
