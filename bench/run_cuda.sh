#!/usr/bin/env bash
# Everything to check and measure on a CUDA machine, in parts that each fit one run of a few
# minutes: the test suite, kernel resources, a small frame's graph cut stage by stage (and its small-scene
# paths against the trees), one frame profiled activity by activity (and as a graph), what one
# verdict on every device costs the narrow phase, then the benchmarks the README quotes: scaling with polyhedra and 80-triangle objects up to 1e6,
# and meshes of the sizes of real assets (120 to 12,640 triangles) up to 1e4, 1,280-triangle objects up to 1e5,
# the traversal's options (box test, object boxes, leaf size), deforming meshes refit every frame (1,280
# triangles, up to 1e4), the broad phase alone up to 1e7 boxes, the tree builds (and
# one-shot collide() against python-fcl), and where a frame's host time goes (split at the launch
# and the wait; the host's own speed right after waits of 0.05-50 ms), and `warp-ccd check` on USD animations of
# 10,000 rigid prims and of 100 deforming 10k-triangle meshes, 240 frames each; then continuous collision:
# 1e7 vertex-face and edge-edge queries per second (a simulation's mix and random ones) against Tight
# Inclusion (ipctk, one CPU thread, on a subset) with their agreement (ccd_queries_<tag>.json), and the
# continuous frame against the discrete frame of the same scene up to 1e6 polyhedra (continuous_<tag>.json);
# then clearance: the clearance frame against the discrete one up to 1e6 polyhedra (clearance_<tag>.json), and
# the least distance of two meshes of 1e4 and 1e5 triangles against python-fcl with its builds (distance_<tag>.json);
# then self-intersection: one 1.3M-triangle mesh against pymeshlab, and 1e2 to 1e3 deforming 10k-triangle
# sheets per frame, self plus pairwise (self_intersection_<tag>.json); then worlds: 4,096 worlds of 20 objects
# against the same objects in one world, a Python loop over worlds and newton's per-world broad phase, the cost
# of filters, a frame from device arrays with Warp's memcpy activities counted (worlds_<tag>.json).
#
#   bash bench/run_cuda.sh                 # every part; results in bench/results/ (or $OUT when set)
#   bash bench/run_cuda.sh tests scaling   # some parts: tests, resources, stages, profile, narrow, scaling, spheres, boxes, deforming,
#                                          # broad, build, host, usd, distributed, ccd, continuous, clearance, contacts,
#                                          # trimesh, distance, self, worlds
#   DEVICE=cpu SMOKE=1 bash bench/run_cuda.sh   # tiny sizes, to check the script itself
#
# Where the tree is a copy whose git (if any) does not describe it, set WARP_CCD_GIT_COMMIT (and
# WARP_CCD_GIT_DIRTY=0|1) so that the logs and result files name the commit they measured. The
# suite runs each test on $DEVICE only (the CPU is what CI covers; set TEST_DEVICES=cpu,cuda for
# both; TESTS="tests/test_[a-c]*" runs some test files); the tests that compare the CPU with CUDA live still run
# wherever Warp has both.
# Needs warp-lang (CUDA build), numpy and pytest; python-fcl, newton, ipctk and matplotlib are optional
# (a missing peer is skipped with a note). Each step runs even if an earlier one failed; the exit
# status is that of the first failure.
set -u
cd "$(dirname "$0")/.."
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
device=${DEVICE:-cuda:0}
out=${OUT:-bench/results}
tag=${device//:/}
parts=${*:-tests resources stages profile narrow scaling spheres boxes deforming broad build host usd distributed ccd continuous clearance contacts trimesh distance self worlds}
mkdir -p "$out"
if [ -n "${SMOKE:-}" ]; then
    big="100 300"; spheres="100"; boxes="1000 3000"; frames=2; tests="tests/test_pipeline.py"; narrow=2000
    profiled="100"; hosted="300"; waits="0.05 5"; builds="100x20 10x80 1x1280"; small="32"; rebuild="2x320"
    usd="--frames 4 --rigid 200 --deforming 3 --fcl-every 2"
    distributed="--objects 200 --frames 8 --long-frames 40 --layers 2 --batch 4 --batch-objects 50 --batch-frames 6"
    mixed="20 50"; boxcases="poly:200 80:100"; deforming="30"; level=2; staged="poly:100"; staged_big="poly:300"
    ccd="--queries 4000 --objects 100 --ipctk-queries 1000 --repeats 2"; continuous="100 300"
    clearance="100 300"; profiled_contacts=300; distance="--triangles 1e3 4e3"; selfargs="--mesh-triangles 2e4 --sheets 4 --crumpled 4 --sheet-n 20"
    worldargs="--worlds 16 --loop-worlds 4"
else
    big="1e2 1e3 1e4 1e5 1e6"; spheres="1e2 1e3 1e4 1e5"; boxes="1e3 1e4 1e5 1e6 1e7"; frames=20; tests=${TESTS:-tests}
    narrow=100000; profiled="1e3 1e4 1e5"; hosted="1e3 1e5 1e6"; waits="0.05 1 5 20 50"
    builds="1000x20 100000x80 10000x1280 1x1310720 60x5120"; small="16"; rebuild="27x5120"
    usd="--frames 240 --rigid 10000 --deforming 100 --fcl-every 10"
    distributed="${DISTRIBUTED:---objects 10000 --frames 240 --long-frames 2400 --layers 16 --batch 100}"
    mixed="1e3 1e4"; boxcases="poly:1000 poly:1000000 80:100000 1280:10000 mixed:1000"; deforming="1e3 1e4"; level=3
    staged="poly:1000 poly:10000 80:1000 mixed:1000"; staged_big="poly:100000 poly:1000000 80:100000 1280:10000"
    ccd="--queries 1e7 --objects 1e4 --ipctk-queries 2e4 --repeats 10"; continuous="1e3 1e4 1e5 1e6"
    clearance="1e3 1e4 1e5 1e6"; profiled_contacts=1e5; distance="--triangles 1e4 1e5"; selfargs="--mesh-triangles 1.3e6 --sheets 1e2 1e3 --crumpled 1e2"
    worldargs="--worlds 4096 --loop-worlds 256"
fi
status=0
step() { "$@" || { rc=$?; echo "step failed (exit $rc): $*" >&2; [ $status -eq 0 ] && status=$rc; }; }
commit=${WARP_CCD_GIT_COMMIT:-$(git rev-parse HEAD 2>/dev/null || echo unknown)}
gpu=$(python3 -c "import warp as wp; wp.config.quiet = True; print(wp.get_device('$device').name)" 2>/dev/null | tail -n 1)

for part in $parts; do
    case $part in
    tests)
        log="$out/tests_$tag.log"
        { echo "warp_ccd test suite on $device ($gpu), commit $commit, $(date -u +%FT%TZ)"
          python3 -c "import warp, numpy; print('warp', warp.__version__, 'numpy', numpy.__version__)"; } > "$log" 2>&1
        WARP_CCD_TEST_DEVICES=${TEST_DEVICES:-$device} step python3 -m pytest -q -ra $tests -p no:cacheprovider \
            >> "$log" 2>&1
        tail -n 15 "$log" ;;
    resources)
        if [ "$device" = cpu ]; then
            echo "run_cuda.sh: resources skipped: registers and spills are a CUDA device's" >&2
        else
            step python3 -m bench.kernel_resources --device "$device" --out "$out/kernel_resources_$tag.json"
        fi ;;
    stages)
        step python3 -m bench.frame_stages --device "$device" --cases $staged --frames $((frames * 2)) \
            --out "$out/frame_stages_$tag.json"
        step python3 -m bench.frame_stages --device "$device" --cases $staged_big --variants default trees whole \
            --frames $((frames / 2)) --replays 10 --out "$out/frame_stages_big_$tag.json" ;;
    profile)
        step python3 -m bench.profile_frame --device "$device" --objects $profiled --frames $((frames * 5)) \
            --out "$out/profile_$tag.json" ;;
    narrow)
        step python3 -m bench.narrow_phase --device "$device" --objects $narrow \
            --out "$out/narrow_phase_$tag.json" ;;
    scaling)
        step python3 -m warp_ccd.bench --device "$device" --objects $big --triangles poly 80 --frames $frames \
            --warmup 3 --out "$out/scaling_$tag.json" --plot "$out/scaling_$tag.png"
        step python3 -m warp_ccd.bench --device "$device" --objects $mixed --triangles mixed --frames $frames \
            --warmup 3 --peers builtin --out "$out/scaling_mixed_$tag.json" --plot "$out/scaling_mixed_$tag.png" ;;
    boxes)
        step python3 -m bench.box_tests --device "$device" --cases $boxcases --frames $((frames / 2)) \
            --out "$out/box_tests_$tag.json" ;;
    deforming)
        step python3 -m bench.deforming --device "$device" --objects $deforming --level $level \
            --frames $((frames / 2)) --out "$out/deforming_$tag.json" ;;
    spheres)
        step python3 -m warp_ccd.bench --device "$device" --objects $spheres --triangles 1280 --frames $frames \
            --warmup 3 --peers builtin,fcl --out "$out/scaling1280_$tag.json" --plot "$out/scaling1280_$tag.png" ;;
    broad)
        step python3 -m bench.broad_phase --device "$device" --n $boxes --newton-max 1000000 \
            --frames $((frames / 2)) --out "$out/broad_phase_$tag.json" ;;
    build)
        step python3 -m bench.build --device "$device" --cases $builds --small $small --repeats $((frames / 2)) \
            --rebuild "$rebuild" --profile "$out/build_profile_$tag.txt" --out "$out/build_$tag.json" ;;
    host)
        step python3 -m bench.host_breakdown --device "$device" --objects $hosted --triangles 80 --frames $frames \
            --out "$out/host_breakdown_$tag.json"
        step python3 -m bench.host_after_wait --device "$device" --waits $waits \
            --out "$out/host_after_wait_$tag.json" ;;
    usd)
        step python3 -m bench.usd_check --device "$device" $usd --out "$out/usd_check_$tag.json" ;;
    distributed)
        step python3 -m bench.distributed --device "$device" $distributed --out "$out/distributed_$tag.json" ;;
    ccd)
        step python3 -m bench.ccd_queries --device "$device" $ccd --out "$out/ccd_queries_$tag.json" ;;
    continuous)
        step python3 -m bench.continuous --device "$device" --objects $continuous --frames $frames --warmup 3 --profile \
            --out "$out/continuous_$tag.json" ;;
    clearance)
        step python3 -m bench.clearance --device "$device" --objects $clearance --clearance 0.05 0.2 \
            --frames $frames --warmup 3 --profile --out "$out/clearance_$tag.json" ;;
    contacts)
        step python3 -m bench.contacts --device "$device" --objects $clearance --frames $((frames / 2)) --warmup 2 \
            --out "$out/contacts_$tag.json"
        step python3 -m bench.contacts_profile "$profiled_contacts" > "$out/contacts_profile_$tag.txt" 2>&1 ;;
    trimesh)
        step python3 -m bench.trimesh_manager --device "$device" --out "$out/trimesh_manager_$tag.json" ;;
    distance)
        step python3 -m bench.distance --device "$device" $distance --gap 0.5 0.01 --frames $frames \
            --warmup 3 --profile --out "$out/distance_$tag.json" ;;
    self)
        step python3 -m bench.self_intersection --device "$device" $selfargs --frames $frames --warmup 3 \
            --out "$out/self_intersection_$tag.json" ;;
    worlds)
        step python3 -m bench.worlds --device "$device" $worldargs --frames $frames --warmup 3 \
            --out "$out/worlds_$tag.json" ;;
    *)
        echo "run_cuda.sh: unknown part $part (tests, resources, profile, narrow, scaling, spheres, boxes, deforming, broad, build," \
            "host, usd, distributed, ccd, continuous, clearance, distance, self, worlds)" >&2
        status=2 ;;
    esac
done
exit $status
