#!/usr/bin/env bash
# Renders an animation's frames on a Slurm cluster as a job array: each
# array task renders one slice of the frame range with `--resume` (a
# retried or requeued task skips the frames it already wrote), and the
# simulation's state passes between tasks through the cache folder
# (SLICELIGHT_CACHE_DIR, default a `cache` folder next to the outputs,
# which must be on storage every node sees): a task starts from the latest
# state cached at or before its first frame. The simulation is
# deterministic, so the frames equal one long local render.
#
#   scripts/slurm-frames.sh SCENE OUT_PATTERN FIRST END [options] [-- sbatch options]
#     OUT_PATTERN   e.g. out/smoke_%04d.png (a frame-number field; give -o more
#                   than once with --also)
#     FIRST END     frames FIRST..END, END excluded
#   options:
#     --per-task N  frames per array task (default 8)
#     --fps F       frames per second (default 24)
#     --sequential  one task at a time, in order (--array ...%1): each task
#                   continues the previous one's simulation instead of
#                   re-simulating from the last state before it; best when
#                   the simulation costs more than the frames
#     --binary B    the slicelight binary (default: the release build)
#     --also PAT    another output pattern (e.g. out/smoke_%04d.exr)
#     --dry-run     print the sbatch script instead of submitting it
#
# Prints the job id. Needs sbatch on the PATH.
set -euo pipefail
usage() { sed -n '2,27p' "$0" >&2; exit 2; }
[ $# -ge 4 ] || usage
scene=$1 pattern=$2 first=$3 end=$4
shift 4
per_task=8 fps=24 sequential=0 dry=0
binary="${CARGO_TARGET_DIR:-$HOME/.cache/slicelight/target}/release/slicelight"
outputs=("-o" "$pattern")
sbatch_extra=()
while [ $# -gt 0 ]; do
    case $1 in
        --per-task) per_task=$2; shift 2 ;;
        --fps) fps=$2; shift 2 ;;
        --sequential) sequential=1; shift ;;
        --binary) binary=$2; shift 2 ;;
        --also) outputs+=("-o" "$2"); shift 2 ;;
        --dry-run) dry=1; shift ;;
        --) shift; sbatch_extra=("$@"); break ;;
        *) echo "slurm-frames: unknown option $1" >&2; usage ;;
    esac
done
for n in "$first" "$end" "$per_task"; do
    [[ $n =~ ^[0-9]+$ ]] || { echo "slurm-frames: expected whole numbers, got $n" >&2; exit 2; }
done
[ "$end" -gt "$first" ] || { echo "slurm-frames: END ($end) must be above FIRST ($first)" >&2; exit 2; }
[ "$per_task" -gt 0 ] || { echo "slurm-frames: --per-task must be at least 1" >&2; exit 2; }
[ -f "$scene" ] || { echo "slurm-frames: $scene: no such scene file" >&2; exit 2; }
[ -x "$binary" ] || { echo "slurm-frames: $binary: not built (cargo build --release)" >&2; exit 2; }
scene=$(realpath "$scene")
binary=$(realpath "$binary")
out_dir=$(dirname "$(realpath -m "$pattern")")
mkdir -p "$out_dir"
cache="${SLICELIGHT_CACHE_DIR:-$out_dir/cache}"
tasks=$(( (end - first + per_task - 1) / per_task ))
array="0-$((tasks - 1))"
[ "$sequential" = 1 ] && array="$array%1"
abs_outputs=()
for ((i = 0; i < ${#outputs[@]}; i += 2)); do
    abs_outputs+=("-o" "$(realpath -m "${outputs[i + 1]}")")
done
script=$(cat <<SCRIPT
#!/usr/bin/env bash
#SBATCH --job-name=slicelight-frames
#SBATCH --array=$array
#SBATCH --output=$out_dir/slurm-%A_%a.log
#SBATCH --requeue
set -euo pipefail
a=\$(( $first + SLURM_ARRAY_TASK_ID * $per_task ))
b=\$(( a + $per_task ))
[ "\$b" -gt $end ] && b=$end
export SLICELIGHT_CACHE_DIR="$cache"
exec "$binary" render "$scene" $(printf '%q ' "${abs_outputs[@]}")--frames "\$a..\$b" --fps $fps --resume --backend auto
SCRIPT
)
if [ "$dry" = 1 ]; then
    echo "$script"
    exit 0
fi
echo "$script" | sbatch --parsable "${sbatch_extra[@]}"
