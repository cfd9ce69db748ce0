#!/usr/bin/env bash
# FMI compliance and robustness checks beyond ctest/pytest (docs/checks.md),
# run by scripts/test.sh after scripts/setup.sh:
#   1. an AddressSanitizer + UndefinedBehaviorSanitizer build (clang) in
#      build-asan/, running every ctest there (C unit tests, the conformance
#      and parallel drivers);
#   2. valgrind memcheck (no leaks, no invalid access) of the conformance
#      driver and of the parallel driver over the Release FMU and of the
#      single-wheel rig's tests (its model and its FMI layer), and helgrind
#      (data races) of the parallel driver;
#   3. short time-bounded libFuzzer runs of the terrain reader and of both
#      FMUs' state deserializers from their committed corpora, two at a time;
#   4. both FMUs' win64 binaries cross-compiled with mingw-w64 into
#      build-win64/dist/JunoRover.fmu and build-win64/dist/WheelRig.fmu
#      (linux64 + win64), each DLL's export table checked against the FMI
#      functions of fmu_src/fmi2.h, and under wine the rover's conformance
#      and parallel drivers and the rig's tests (its model, its FMI layer);
#   5. libcosimpy installed into .venv for tests/python/test_importers.py.
# Debian packages are installed only if missing.  Environment:
#   JUNO_FUZZ_SECONDS (default 20) per fuzz target (three targets, two at a
#   time: twice that in all),
#   JUNO_CHECKS_WINE=0 to skip wine (the cross build and export check stay).
set -euo pipefail
cd "$(dirname "$0")/.."
t_start=$SECONDS
fuzz_seconds=${JUNO_FUZZ_SECONDS:-20}
summary=()
note() { summary+=("$1"); echo "checks: $1"; }

# ---------------------------------------------------------------- tools
need_apt=()
command -v valgrind >/dev/null || need_apt+=(valgrind)
command -v clang >/dev/null || need_apt+=(clang libclang-rt-dev)   # libclang-rt: libFuzzer, sanitizer runtimes
command -v x86_64-w64-mingw32-gcc >/dev/null || need_apt+=(gcc-mingw-w64-x86-64 binutils-mingw-w64-x86-64)
[ "${JUNO_CHECKS_WINE:-1}" = 0 ] || [ -x /usr/lib/wine/wine64 ] || command -v wine64 >/dev/null || need_apt+=(wine64)
SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
apt_install() {
  echo "checks: installing Debian packages: $*"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "$@" >/dev/null
}
[ ${#need_apt[@]} -eq 0 ] || apt_install "${need_apt[@]}"
# libFuzzer and the sanitizer runtimes of Debian's clang are a separate package
probe=$(mktemp -d)
printf 'int LLVMFuzzerTestOneInput(const unsigned char *d, unsigned long n) { (void)d; (void)n; return 0; }\n' >"$probe/f.c"
if ! clang -fsanitize=fuzzer,address,undefined "$probe/f.c" -o "$probe/f" 2>/dev/null; then
  ver=$(clang -dumpversion | cut -d. -f1)
  apt_install "libclang-rt-$ver-dev"
fi
rm -rf "$probe"
wine=""
if [ "${JUNO_CHECKS_WINE:-1}" != 0 ]; then
  if [ -x /usr/lib/wine/wine64 ]; then wine=/usr/lib/wine/wine64; else wine=$(command -v wine64 || true); fi
fi
if ! .venv/bin/python -c 'import libcosimpy' 2>/dev/null; then
  echo "checks: installing libcosimpy into .venv"
  .venv/bin/python -m pip install -q libcosimpy==0.0.6
fi

# ------------------------------------------- 1. sanitizers (ASan + UBSan)
t0=$SECONDS
echo "== checks: AddressSanitizer + UndefinedBehaviorSanitizer build (build-asan)"
CC=clang cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DJUNO_SANITIZE=ON -DJUNO_FUZZ=ON -DJUNO_WERROR=ON >/dev/null
cmake --build build-asan
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1:strict_string_checks=1:detect_stack_use_after_return=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
(cd build-asan && ctest --output-on-failure)
note "ASan+UBSan: $(cd build-asan && ctest -N | tail -1 | sed 's/Total Tests: //') ctest programs clean ($((SECONDS - t0)) s)"

# --------------------------------------------------------- 2. valgrind
t0=$SECONDS
echo "== checks: valgrind memcheck and helgrind (Release FMU, build/)"
# The benchmark programs are built on demand (juno bench): built here too, so that a change of the
# model's structs that they mirror fails the checks, not a user's benchmark.
cmake --build build --target conformance parallel test_wheel_rig test_wheel_rig_fmi bench_contact bench_fmu
vg=(valgrind -q --error-exitcode=97 --leak-check=full --show-leak-kinds=definite,indirect,possible
    --errors-for-leak-kinds=definite,indirect,possible --track-origins=yes)
"${vg[@]}" build/conformance build/fmu build | tail -1
"${vg[@]}" build/parallel build/fmu build 4 30 | tail -1
valgrind -q --tool=helgrind --error-exitcode=98 --suppressions=tests/conformance/helgrind.supp \
  build/parallel build/fmu build 4 30 | tail -1
# the single-wheel rig (WheelRig.fmu): its model, and its FMI layer as a host calls it
"${vg[@]}" build/test_wheel_rig | tail -1
"${vg[@]}" build/test_wheel_rig_fmi | tail -1
note "valgrind: memcheck of conformance, parallel and the rig's tests, helgrind of parallel: no errors, no leaks ($((SECONDS - t0)) s)"

# ------------------------------------------------------------ 3. fuzzing
# Three targets, each for fuzz_seconds, at most fuzz_jobs at a time: the terrain reader and both
# FMUs' state deserializers (fuzz_state: JunoRover, fuzz_rig_state: WheelRig).  A state target
# starts from the committed corpus and from this build's own seeds (a valid state of the current
# layout, which a committed one may no longer match).
t0=$SECONDS
fuzz_targets=(terrain state rig_state)
fuzz_jobs=2
echo "== checks: libFuzzer, ${fuzz_seconds} s per target, ${fuzz_jobs} at a time"
fuzz_dir=$(mktemp -d)
trap 'rm -rf "$fuzz_dir"' EXIT
: >"$fuzz_dir/empty"
run_fuzz() {
  local target=$1 fuzzer="$PWD/build-asan/fuzz_$1"
  mkdir -p "$fuzz_dir/$target"
  if [ "$target" != terrain ]; then
    JUNO_FUZZ_SEEDS="$fuzz_dir/$target" "$fuzzer" "$fuzz_dir/empty" >"$fuzz_dir/$target.seeds.log" 2>&1 ||
      { cat "$fuzz_dir/$target.seeds.log"; return 1; }
  fi
  (cd "$fuzz_dir" && "$fuzzer" "$fuzz_dir/$target" "$OLDPWD/tests/fuzz/corpus_$target" \
      -max_total_time="$fuzz_seconds" -timeout=30 -rss_limit_mb=4096 -seed=1 -print_final_stats=1 \
      >"$fuzz_dir/$target.log" 2>&1)
}
fuzz_failed=0
running=0
for target in "${fuzz_targets[@]}"; do
  if [ "$running" -ge "$fuzz_jobs" ]; then
    wait -n || fuzz_failed=1
    running=$((running - 1))
  fi
  run_fuzz "$target" &
  running=$((running + 1))
done
while [ "$running" -gt 0 ]; do
  wait -n || fuzz_failed=1
  running=$((running - 1))
done
for target in "${fuzz_targets[@]}"; do
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$fuzz_dir/$target.log" 2>/dev/null)
  echo "fuzz_$target: ${runs:-?} executions"
  summary+=("fuzz_$target: ${runs:-?} executions in ${fuzz_seconds} s")
done
if [ "$fuzz_failed" != 0 ]; then
  for target in "${fuzz_targets[@]}"; do tail -40 "$fuzz_dir/$target.log" 2>/dev/null || true; done
  # kept out of the temporary folder, which goes on exit
  mkdir -p build-asan/fuzz-artifacts
  cp "$fuzz_dir"/crash-* "$fuzz_dir"/timeout-* "$fuzz_dir"/leak-* build-asan/fuzz-artifacts/ 2>/dev/null || true
  ls build-asan/fuzz-artifacts
  echo "checks: a fuzz target failed: reproduce with build-asan/fuzz_TARGET build-asan/fuzz-artifacts/FILE" >&2
  exit 1
fi
note "fuzzing: no crash, leak or timeout ($((SECONDS - t0)) s)"

# ------------------------------------------------------------ 4. Windows
t0=$SECONDS
echo "== checks: win64 cross build with mingw-w64 (build-win64)"
cmake -S . -B build-win64 -G Ninja -DCMAKE_TOOLCHAIN_FILE=cmake/mingw-w64-x86_64.cmake \
  -DCMAKE_BUILD_TYPE=Release -DJUNO_WERROR=ON -DJUNO_HOST_FMU_DIR="$PWD/build/fmu" \
  -DJUNO_HOST_RIG_FMU_DIR="$PWD/build/fmu-rig" >/dev/null
cmake --build build-win64 --target JunoRover WheelRig conformance parallel test_wheel_rig test_wheel_rig_fmi fmu_win64
expected=$(sed -n 's/^FMI2_EXPORT [^(]*[ *]\(fmi2[A-Za-z]*\)(.*/\1/p' fmu_src/fmi2.h | sort)
for fmu in JunoRover WheelRig; do
  exported=$(x86_64-w64-mingw32-objdump -p "build-win64/$fmu.dll" |
    sed -n '/\[Ordinal\/Name Pointer\] Table/,/^$/s/^\s*\[ *[0-9]*\] \(.*\)$/\1/p' | sort)
  if [ "$expected" != "$exported" ]; then
    echo "checks: $fmu.dll exports differ from fmu_src/fmi2.h:" >&2
    diff <(echo "$expected") <(echo "$exported") >&2 || true
    exit 1
  fi
  imports=$(x86_64-w64-mingw32-objdump -p "build-win64/$fmu.dll" | sed -n 's/^\s*DLL Name: //p' | tr '\n' ' ')
  note "win64: $fmu.dll exports exactly the $(echo "$expected" | wc -l) fmi2 functions of fmi2.h; imports: $imports"
done
.venv/bin/python - <<'EOF'
from fmpy.validation import validate_fmu
import zipfile
for model in ("JunoRover", "WheelRig"):
    fmu = f"build-win64/dist/{model}.fmu"
    problems = validate_fmu(fmu)
    assert not problems, (fmu, problems)
    names = zipfile.ZipFile(fmu).namelist()
    assert f"binaries/win64/{model}.dll" in names and f"binaries/linux64/{model}.so" in names, (fmu, names)
    print("checks: fmpy validate", fmu, "(linux64 + win64): no problems")
EOF
if [ -n "$wine" ]; then
  export WINEPREFIX="$PWD/build-win64/wineprefix" WINEDEBUG=-all
  # A driver's last line is its summary ("N passed, M failed").  Output without one means wine
  # itself did not run the program (seen once in CI: no output at all, exit 1, and never again in
  # 4 fresh-prefix runs under load); that, and only that, is retried once on a restarted
  # wineserver.  On a failure the whole log is shown.
  # run_under_wine PROGRAM [ARGUMENTS...]
  run_under_wine() {
    local log="build-win64/$(basename "$1" .exe).log" attempt
    for attempt in 1 2; do
      if "$wine" "$@" >"$log" 2>&1; then tail -1 "$log"; return 0; fi
      if grep -q '^[0-9]* passed, [0-9]* failed$' "$log"; then cat "$log" >&2; return 1; fi
      echo "checks: wine gave no summary for $1 (attempt $attempt); its output:" >&2
      cat "$log" >&2
      "$(dirname "$wine")/wineserver" -k 2>/dev/null || true
    done
    return 1
  }
  run_under_wine build-win64/conformance.exe build-win64/fmu-all build-win64
  run_under_wine build-win64/parallel.exe build-win64/fmu-all build-win64
  # the rig's tests, built for win64 from the sources of WheelRig.dll: its model, and its FMI
  # layer as a host calls it
  run_under_wine build-win64/test_wheel_rig.exe
  run_under_wine build-win64/test_wheel_rig_fmi.exe
  note "win64 under wine: the rover's conformance and parallel drivers and the rig's tests passed ($((SECONDS - t0)) s)"
else
  note "win64: wine skipped (JUNO_CHECKS_WINE=0) ($((SECONDS - t0)) s)"
fi

echo "== checks: summary ($((SECONDS - t_start)) s)"
printf '  %s\n' "${summary[@]}"
