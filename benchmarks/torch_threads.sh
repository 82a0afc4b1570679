#!/bin/bash
# Seconds per episode of one evaluation worker by --eval.torch_threads, on an idle machine and with one busy loop
# per core: docs/performance.md, "torch threads". Usage:
#   bash benchmarks/torch_threads.sh BENCHMARK_DIR CHECKPOINT_DIR [SPLIT] [OUT_DIR]
# Prints one line per run (name, threads, wall seconds with start-up, load average); the s/episode figures are
# the progress bar's elapsed time over the episodes, in OUT_DIR/<name>.log.
set -u
BENCH=$1; CKPT=$2; SPLIT=${3:-libero_color}; OUT=${4:-outputs/torch_threads}
mkdir -p "$OUT"
run() {  # name threads
  rm -rf "$OUT/$1"
  local start end
  start=$(date +%s.%N)
  .venv/bin/roboview-evaluate --benchmark.path="$BENCH" --benchmark.splits="$SPLIT" --policy.type=lerobot \
    --policy.path="$CKPT" --policy.device=cpu --eval.num_workers=1 --eval.limit=3 --eval.n_repeats=1 \
    --eval.torch_threads="$2" --output_dir="$OUT/$1" > "$OUT/$1.log" 2>&1
  end=$(date +%s.%N)
  echo "$1 threads=$2 wall=$(python3 -c "print(round($end - $start, 1))") load=$(cut -d' ' -f1 /proc/loadavg)"
}
run idle_t2 2
run idle_t1 1
busy=()
for _ in $(seq "$(nproc)"); do python3 -c "while True: pass" & busy+=($!); done
sleep 20
run load_t2 2
run load_t1 1
run load_t0 0
kill "${busy[@]}"
