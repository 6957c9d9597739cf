#!/usr/bin/env bash
# Submits a gap-bench campaign to Slurm as three chained jobs: the calibration (once), an
# array of SHARDS shards that read it, and the merge. Run it on the login node:
#
#   submit.sh WORKDIR SHARDS GAP-BENCH-OPTIONS...
#   e.g. submit.sh /shared/$USER/bench-9301 8 --source independent --cases 10 --seed 9301
#
# WORKDIR must be on a filesystem every node sees (the shards write their parts there and
# the merge reads them); it must be new or empty. The binary is copied into WORKDIR/bin, so
# the nodes need no build and no repository: the independent model is built into it (the
# bridge source also needs make and cc on the nodes, or `--programs DIR` on the shared
# filesystem). Results: WORKDIR/bench.md; logs: WORKDIR/logs/.
#
# Environment: EYEBOT_HIL, the binary to stage (default: `eyebot-hil` on PATH);
# GAP_CPUS_PER_TASK, CPUs per job (default 2; rayon uses exactly these); sbatch's own
# SBATCH_* variables (SBATCH_PARTITION, SBATCH_ACCOUNT, ...) reach every job.
# Prints the three job ids: calibration, array, merge.
set -euo pipefail

usage() {
  echo "usage: $0 WORKDIR SHARDS GAP-BENCH-OPTIONS..." >&2
  exit 2
}
[ "$#" -ge 2 ] || usage
work=$1
shards=$2
shift 2
case "$shards" in
  '' | *[!0-9]* | 0) echo "$0: SHARDS must be a whole number >= 1, got \`$shards\`" >&2; exit 2 ;;
esac
here=$(cd "$(dirname "$0")" && pwd)
binary=${EYEBOT_HIL:-$(command -v eyebot-hil || true)}
if [ -z "$binary" ] || [ ! -x "$binary" ]; then
  echo "$0: no eyebot-hil binary to stage (set EYEBOT_HIL=PATH or put eyebot-hil on PATH)" >&2
  exit 1
fi
cpus=${GAP_CPUS_PER_TASK:-2}

mkdir -p "$work"
work=$(cd "$work" && pwd)
if [ -n "$(ls -A "$work")" ]; then
  echo "$0: $work is not empty; a campaign needs a new or empty directory" >&2
  exit 1
fi
mkdir -p "$work/bin" "$work/parts" "$work/logs"
cp "$binary" "$work/bin/eyebot-hil"

common=(--parsable --chdir="$work" --cpus-per-task="$cpus")
calibration=$(sbatch "${common[@]}" --job-name=gap-calibrate \
  --output="$work/logs/calibrate-%j.out" "$here/calibrate.sbatch" "$@")
array=$(sbatch "${common[@]}" --job-name=gap-shard --array="1-$shards" \
  --dependency="afterok:$calibration" --kill-on-invalid-dep=yes \
  --output="$work/logs/shard-%A_%a.out" "$here/shard.sbatch" "$@")
merge=$(sbatch "${common[@]}" --job-name=gap-merge --cpus-per-task=1 \
  --dependency="afterok:$array" --kill-on-invalid-dep=yes \
  --output="$work/logs/merge-%j.out" "$here/merge.sbatch")
echo "$calibration $array $merge"
