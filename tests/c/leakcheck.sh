#!/usr/bin/env bash
# The long leak check of issue 9 (not part of `make test`): the C harness
# (fmu_src/testing/test_harness.c) runs N instantiate / initialise / step / reset /
# free cycles (default 10000), with every error path, threads and corrupted
# FMU states, under valgrind (default) or LeakSanitizer, and prints the
# figures (bytes lost) that docs/robustness.md quotes.
#
#   [CORRUPT=R] tests/c/leakcheck.sh [valgrind|lsan] [CYCLES]   (R corrupted FMU states, default 300)
#
# Run from anywhere; needs gcc, the project's .venv (for fmpy's FMI headers)
# and a built build/gen (make fmu).
set -euo pipefail
cd "$(dirname "$0")/../.."
MODE=${1:-valgrind}
CYCLES=${2:-10000}
PY=.venv/bin/python
[ -x "$PY" ] || PY=python3
FMI=$("$PY" -c "import fmpy, pathlib; print(pathlib.Path(fmpy.__file__).parent / 'c-code')")
"$PY" -c "from lss_fmu import build; build.generate(); (build.GEN / 'lss_guid.h').exists() or build.build_fmu(quiet=True)"
URI=$("$PY" -c "import pathlib; print(pathlib.Path('fmu_src/resources').resolve().as_uri())")
SRCS=$(ls fmu_src/*.c)
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
ARGS=("$URI" --cycles "$CYCLES" --stop 0.0001 --step 0.0001 --threads 4 --corrupt "${CORRUPT:-300}")
case "$MODE" in
valgrind)
    command -v valgrind >/dev/null || { echo "valgrind not installed (try: $0 lsan)"; exit 2; }
    gcc -std=c11 -O1 -g -Wall -Wextra -Werror -I build/gen -I fmu_src -I "$FMI" -o "$OUT/harness" \
        fmu_src/testing/test_harness.c $SRCS build/gen/lss_vars.c -lm -lpthread
    START=$(date +%s)
    valgrind --leak-check=full --show-leak-kinds=all --errors-for-leak-kinds=all --error-exitcode=99 \
        "$OUT/harness" "${ARGS[@]}" 2>&1 | grep -E "^==[0-9]+== (HEAP SUMMARY|    in use|  total heap|LEAK SUMMARY|    definitely|    indirectly|    possibly|    still reachable|All heap|ERROR SUMMARY)|^summary|^threads|^corrupt|^error paths|FAIL" || true
    RC=${PIPESTATUS[0]}
    ;;
lsan)
    gcc -std=c11 -O1 -g -fno-omit-frame-pointer -fsanitize=address,undefined -fno-sanitize-recover=all \
        -Wall -Wextra -Werror -I build/gen -I fmu_src -I "$FMI" -o "$OUT/harness" \
        fmu_src/testing/test_harness.c $SRCS build/gen/lss_vars.c -lm -lpthread
    START=$(date +%s)
    ASAN_OPTIONS=detect_leaks=1:halt_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
        "$OUT/harness" "${ARGS[@]}" 2>&1 | tail -20 || true
    RC=${PIPESTATUS[0]}
    ;;
*)
    echo "usage: $0 [valgrind|lsan] [CYCLES]"; exit 2 ;;
esac
echo "mode $MODE, $CYCLES cycles, $(( $(date +%s) - START )) s, exit code $RC"
exit "$RC"
