#!/usr/bin/env bash
# The GPU figures of BENCHMARKS.md ("GPU: an NVIDIA H200"), measured again on a machine with a
# CUDA device: `bash benchmarks/gpu_figures.sh OUT_DIR [DEVICE]` (DEVICE defaults to cuda:0).
# Writes OUT_DIR/log.txt, OUT_DIR/opt_level-cuda.json (the compiler level's study), one
# OUT_DIR/bench-*.json per `warpsim bench` run and OUT_DIR/speed-cuda.json; each run has its
# own time limit, so one slow run (the study's build of the ballistic kernel at Warp's default
# compiler level takes about 4 minutes) cannot take the others' time.
set -uo pipefail
out=${1:?usage: gpu_figures.sh OUT_DIR [DEVICE]}
device=${2:-cuda:0}
mkdir -p "$out"
export PYTHONUNBUFFERED=1
log() { echo "== $(date +%T) $*" | tee -a "$out/log.txt"; }
bench() {  # bench TAG LIMIT_S ARGS...
    local tag=$1 limit=$2
    shift 2
    log "warpsim bench $* --device $device"
    timeout "$limit" python -m warpsim bench "$@" --device "$device" \
        --json "$out/bench-$tag.json" 2>&1 | tee -a "$out/log.txt"
}
log "python -m benchmarks.opt_level --device $device --rounds 2"
timeout 600 python -m benchmarks.opt_level --device "$device" --rounds 2 \
    --out "$out/opt_level-cuda.json" 2>&1 | tee -a "$out/log.txt"
bench room-1e6 120 room -n 1000000 --frames 300
bench room-1e6-f64 120 room -n 1000000 --frames 300 --precision float64
bench room-1e6-ballistic 120 room -n 1000000 --frames 300 --motion ballistic
bench room-1e6-ballistic-f64 120 room -n 1000000 --frames 300 --motion ballistic \
    --precision float64
bench thin-1e6 120 thin-walls -n 1000000 --frames 100
log "python -m benchmarks.speed --device $device --only room"
timeout 300 python -m benchmarks.speed --device "$device" --only room \
    --out "$out/speed-cuda.json" 2>&1 | tee -a "$out/log.txt"
bench room-1e7 180 room -n 10000000 --frames 100
bench room-1e7-ballistic 180 room -n 10000000 --frames 100 --motion ballistic
bench room-1e8 400 room -n 100000000 --frames 20
log done
