#!/usr/bin/env bash
# Everything to check and measure on a CUDA machine in one go: the test suite on every Warp
# device, then the benchmarks the README quotes (scaling with 80-triangle objects up to 1e6,
# 1,280-triangle objects up to 1e5, the broad phase alone up to 1e7 boxes).
#
#   bash bench/run_cuda.sh            # results in bench/results/ (or in $OUT when it is set)
#   DEVICE=cpu SMOKE=1 bash bench/run_cuda.sh   # tiny sizes, to check the script itself
#
# Needs warp-lang (CUDA build), numpy and pytest; python-fcl, newton and matplotlib are optional
# (a missing peer is skipped with a note). Each step runs even if an earlier one failed; the exit
# status is that of the first failure.
set -u
cd "$(dirname "$0")/.."
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
device=${DEVICE:-cuda:0}
out=${OUT:-bench/results}
tag=${device//:/}
mkdir -p "$out"
if [ -n "${SMOKE:-}" ]; then
    big="100 300"; spheres="100"; boxes="1000 3000"; frames=2; tests="tests/test_pipeline.py"
else
    big="1e2 1e3 1e4 1e5 1e6"; spheres="1e2 1e3 1e4 1e5"; boxes="1e3 1e4 1e5 1e6 1e7"; frames=20; tests="tests"
fi
status=0
step() { "$@" || { rc=$?; echo "step failed (exit $rc): $*" >&2; [ $status -eq 0 ] && status=$rc; }; }

step python3 -m pytest -q $tests -p no:cacheprovider > "$out/tests_$tag.log" 2>&1
tail -n 15 "$out/tests_$tag.log"
step python3 -m warp_ccd.bench --device "$device" --objects $big --triangles 80 --frames $frames --warmup 3 \
    --out "$out/scaling80_$tag.json" --plot "$out/scaling80_$tag.png"
step python3 -m warp_ccd.bench --device "$device" --objects $spheres --triangles 1280 --frames $frames --warmup 3 \
    --peers builtin,fcl --out "$out/scaling1280_$tag.json" --plot "$out/scaling1280_$tag.png"
step python3 bench/bench_broad_phase.py --device "$device" --n $boxes --out "$out/broad_phase_$tag.json"
exit $status
