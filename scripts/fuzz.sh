#!/usr/bin/env bash
# Coverage-guided fuzzing of everything slicelight reads from outside
# (fuzz/README.md): each target in turn, for a fixed time or a fixed number
# of executions, starting from the kept corpus in fuzz/corpus/<target>.
#
#   scripts/fuzz.sh [--seconds N | --runs N] [TARGET ...]
#
# Targets: scene obj image grid cache (all by default). A crash, a hang
# (10 s on one input), a single allocation over 1 GiB or a resident size
# over 2 GiB stops the run with libFuzzer's report and the input under
# fuzz/artifacts/<target>/, and this script exits non-zero. Installs
# cargo-fuzz if it is missing. New inputs libFuzzer finds go to a scratch
# folder, not the kept corpus.
set -euo pipefail
cd "$(dirname "$0")/.."
limit=(-max_total_time=60)
targets=()
while [ $# -gt 0 ]; do
    case "$1" in
        --seconds) limit=(-max_total_time="$2"); shift 2 ;;
        --runs) limit=(-runs="$2"); shift 2 ;;
        -h|--help) sed -n '2,13p' "$0"; exit 0 ;;
        *) targets+=("$1"); shift ;;
    esac
done
[ ${#targets[@]} -gt 0 ] || targets=(scene obj image grid cache)
if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "fuzz: installing cargo-fuzz" >&2
    (cd / && cargo install cargo-fuzz --locked)  # the default toolchain, not the pinned one
fi
# Sanitizer builds in a folder of their own (their flags differ from the
# project's, so sharing would rebuild both each time).
export CARGO_TARGET_DIR="${SLICELIGHT_FUZZ_TARGET_DIR:-$HOME/.cache/slicelight/fuzz-target}"
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
for t in "${targets[@]}"; do
    mkdir -p "$scratch/$t"
    echo "fuzz: $t (${limit[*]})" >&2
    set +e
    cargo fuzz run "$t" "$scratch/$t" "fuzz/corpus/$t" -- \
        "${limit[@]}" -timeout=10 -malloc_limit_mb=1024 -rss_limit_mb=2048 -print_final_stats=1 \
        > "$scratch/$t.log" 2>&1
    status=$?
    set -e
    grep -E "^(INFO: seed|#[0-9]+[[:space:]]+(INITED|DONE)|stat::number_of_executed_units|stat::peak_rss_mb|Done [0-9]+ runs)" \
        "$scratch/$t.log" || true
    if [ "$status" != 0 ]; then
        tail -60 "$scratch/$t.log" >&2
        echo "fuzz: $t FAILED (exit $status); the input is under fuzz/artifacts/$t/" >&2
        exit 1
    fi
done
