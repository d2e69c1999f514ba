#!/usr/bin/env bash
# Reproduce the tables of docs/RESULTS.md (about an hour, one core at a time); OUT/summary.md
# holds the tables that compare runs (benchmarks/results_summary.py).
# Usage: bash benchmarks/results.sh [OUT_DIR] [PART]   (needs ../shared/data or $POSEDRIFT_DATA)
# PART is all (the default), tables, repeats, smooth or speed: on a two-core machine run
# "tables" and "repeats" side by side (two commands, one core each), then "smooth" and "speed".
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
data="${POSEDRIFT_DATA:-$here/../shared/data}"
out="${1:-results}"
part="${2:-all}"
case "$part" in all|tables|repeats|smooth|speed) ;; *) echo "unknown part: $part" >&2; exit 2;; esac
mkdir -p "$out"
M="$data/mocap"
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
methods=cpd,shotton,pda,icp
# The headline tables also run the tracker with the frontal net alone (cpd-frontal), without
# the back net (cpd-noback), without the side net (cpd-noside), without the part nets
# (cpd-forest: the forest labels its pixels), without ICP's second opinion (cpd-nofallback)
# and Shotton et al.'s joints from the net's labels (shotton-net).
wide=cpd,cpd-frontal,cpd-noback,cpd-noside,cpd-forest,cpd-nofallback,shotton,shotton-net,pda,icp
# Table 1's development and held-out clips (less the built-in motion), for the runs nearer
# the camera.
close_clips=("$M/cmu/002_05.bvh" "$M/cmu/002_07.bvh" "$M/cmu/002_10.bvh" "$M/cmu/001_08.bvh"
    "$M/cmu-original-skeleton/131_03.bvh" "$M/cmu/007_03.bvh" "$M/cmu/007_05.bvh"
    "$M/cmu/007_08.bvh")

tables() {
# Table 1 on development clips the default forest was trained on, and on held-out clips.
posedrift -q eval synthetic builtin "$M/cmu/002_05.bvh" "$M/cmu/002_07.bvh" "$M/cmu/002_10.bvh" \
    "$M/cmu/001_08.bvh" --frames 500 --methods "$wide" --json "$out/table1_dev.json" \
    --figures "$out/figures_dev" | tee "$out/table1_dev.md"
posedrift -q eval synthetic "$M/cmu-original-skeleton/131_03.bvh" "$M/cmu/007_03.bvh" \
    "$M/cmu/007_05.bvh" "$M/cmu/007_08.bvh" --frames 500 --methods "$wide" \
    --json "$out/table1_heldout.json" | tee "$out/table1_heldout.md"
# The rest of subject 007: nine more walks that no model saw (the forest and nets leave 007 out).
posedrift -q eval synthetic "$M"/cmu/007_0{1,2,4,6,7,9}.bvh "$M"/cmu/007_1{0,1,2}.bvh \
    --frames 500 --methods "$methods" --json "$out/unseen_007.json" | tee "$out/unseen_007.md"
# With Kinect-like depth noise.
posedrift -q eval synthetic builtin "$M/cmu/002_07.bvh" --frames 500 --noise \
    --methods "$methods,cpd-forest" --json "$out/table1_noise.json" | tee "$out/table1_noise.md"
# The same in a room: a floor and a wall that every method must segment away.
posedrift -q eval synthetic builtin "$M/cmu/002_07.bvh" --frames 500 --noise --room \
    --methods "$methods,cpd-forest" --json "$out/table1_room.json" | tee "$out/table1_room.md"
# A 640 x 480 camera: the tracker on every other pixel (the default) and on every pixel.
for d in 2.0 3.5; do
    posedrift -q eval synthetic builtin "$M/cmu/007_03.bvh" "$M/cmu/002_07.bvh" \
        "$M/cmu-original-skeleton/131_03.bvh" --frames 300 --noise --room --camera d435 \
        --distance "$d" --methods cpd,cpd-fullres --no-paper --json "$out/vga_$d.json" \
        | tee "$out/vga_$d.md"
done
# Ablations of the tracker.
ablations=cpd,cpd-paper,icp-paper,cpd-norelabel,cpd-novotes,cpd-rigid,cpd-cold,cpd-reinit,\
cpd-nofallback,cpd-nobrace,cpd-noislands
posedrift -q eval synthetic builtin "$M/cmu/002_07.bvh" --frames 500 \
    --methods "$ablations,cpd-200,cpd-800" \
    --json "$out/ablations.json" --no-paper | tee "$out/ablations.md"
# Drift (first / last 100 frames per sequence in the JSON), and the time of a full
# 500-frame, four-method run.
start=$(date +%s)
posedrift -q eval synthetic builtin --frames 500 --methods "$methods,cpd-paper" \
    --json "$out/drift.json" | tee "$out/drift.md"
echo "500 frames, $methods,cpd-paper: $(( $(date +%s) - start )) s wall" | tee "$out/drift_time.txt"
# Other bodies: the held-out clips with a tall, thin and a short, wide person.
for body in "1.95 0.9" "1.55 1.15"; do
    set -- $body
    posedrift -q eval synthetic "$M/cmu-original-skeleton/131_03.bvh" "$M/cmu/007_03.bvh" \
        "$M/cmu/007_05.bvh" "$M/cmu/007_08.bvh" --frames 500 --height "$1" --girth "$2" \
        --methods "$methods" --json "$out/body_$1.json" | tee "$out/body_$1.md"
done
# A person too near the camera (1.6 m: head and feet cut off by the image's edges).
posedrift -q eval synthetic builtin "$M/cmu/007_03.bvh" "$M/cmu/007_05.bvh" "$M/cmu/002_07.bvh" \
    --frames 300 --distance 1.6 --methods "$methods" --json "$out/near.json" | tee "$out/near.md"
# Table 1's eight clips nearer the camera (2.0 m): a climber's arms and head, and most
# people's feet, leave the image.
posedrift -q eval synthetic "${close_clips[@]}" --frames 300 --distance 2.0 --methods "$methods" \
    --json "$out/close.json" | tee "$out/close.md"
# A person who starts turned away: side-on (90 degrees, their right side to the camera) and
# with their back to it (180); the protocol's person starts facing the camera.
for f in 90 180; do
    posedrift -q eval synthetic builtin "$M/cmu/007_03.bvh" --frames 300 --facing "$f" \
        --methods "$methods,shotton-net" --json "$out/facing_$f.json" | tee "$out/facing_$f.md"
done
# A camera mounted high (2.2 m) and looking 24 degrees down at the pelvis: the development and
# held-out clips, 300 frames.
posedrift -q eval synthetic builtin "${close_clips[@]}" --frames 300 --camera-height 2.2 \
    --camera-tilt 24 --methods "$methods,cpd-level" --json "$out/tilt.json" | tee "$out/tilt.md"
posedrift -q eval synthetic builtin "$M/cmu/002_07.bvh" "$M/cmu/007_03.bvh" --frames 300 --noise \
    --room --camera-height 2.2 --camera-tilt 24 --methods cpd,icp --json "$out/tilt_room.json" \
    | tee "$out/tilt_room.md"
# Real Kinect recordings: one sequence per action, subject (a mod 4) + 1, trial 1.
seqs=$(for a in $(seq 1 27); do printf "a%d_s%d_t1," "$a" $(( a % 4 + 1 )); done)
posedrift -q eval utd "$data/utd-mhad" --sequences "${seqs%,}" --methods "$wide" \
    --json "$out/utd.json" | tee "$out/utd.md"
# The second trial of every action and subject: recordings the Kinect offsets were not fitted on.
seqs2=$(for a in $(seq 1 27); do for s in 1 2 3 4; do printf "a%d_s%d_t2," "$a" "$s"; done; done)
posedrift -q eval utd "$data/utd-mhad" --sequences "${seqs2%,}" --methods "$wide" \
    --json "$out/utd_trial2.json" | tee "$out/utd_trial2.md"
# The forest's and the part net's pixel accuracy on held-out clips and bodies.
mkdir -p "$out/labels"
posedrift -q synth "$M/cmu/007_01.bvh" --out "$out/labels/h1" --frames 45 --height 1.58 \
    --girth 1.15 --noise --seed 3
posedrift -q synth "$M/cmu/007_05.bvh" --out "$out/labels/h2" --frames 45 --height 1.92 \
    --girth 0.88
posedrift -q synth "$M/cmu/007_10.bvh" --out "$out/labels/h3" --frames 45 --height 1.70 \
    --girth 1.05 --noise --seed 4 --distance 3.2
posedrift -q synth "$M/cmu-original-skeleton/131_03.bvh" --out "$out/labels/h4" --frames 90 \
    --height 1.65 --girth 0.95 --distance 3.0 --camera-height 0.8
for h in h1 h2 h3 h4; do
    posedrift -q eval labels "$out/labels/$h" --json "$out/labels_${h}_forest.json"
    posedrift -q eval labels "$out/labels/$h" --classifier net --json "$out/labels_${h}_net.json"
done
# Drift on the same poses at both ends: each clip's first 250 frames forward, then backward.
posedrift -q eval synthetic builtin "$M/cmu/002_05.bvh" "$M/cmu/002_07.bvh" "$M/cmu/002_10.bvh" \
    "$M/cmu/001_08.bvh" "$M/cmu-original-skeleton/131_03.bvh" "$M/cmu/007_03.bvh" \
    "$M/cmu/007_05.bvh" --frames 500 --there-and-back --methods cpd,shotton,icp \
    --json "$out/there_and_back.json" | tee "$out/there_and_back.md"
}

repeats() {
# The tracker against ICP-style tracking over five point samples each (seeds 0-4), on the
# development and held-out clips, with noise, in a room, a tall body, too near, at 2.0 m,
# and on the UTD-MHAD trials of the Table 1 runs.
repeat() { name=$1; shift; posedrift -q eval synthetic "$@" --methods cpd,icp --repeats 5 \
    --no-paper --json "$out/repeats_$name.json" | tee "$out/repeats_$name.md"; }
repeat dev builtin "$M/cmu/002_05.bvh" "$M/cmu/002_07.bvh" "$M/cmu/002_10.bvh" \
    "$M/cmu/001_08.bvh" --frames 500
repeat heldout "$M/cmu-original-skeleton/131_03.bvh" "$M/cmu/007_03.bvh" "$M/cmu/007_05.bvh" \
    "$M/cmu/007_08.bvh" --frames 500
repeat noise builtin "$M/cmu/002_07.bvh" --frames 500 --noise
repeat room builtin "$M/cmu/002_07.bvh" --frames 500 --noise --room
repeat tall "$M/cmu-original-skeleton/131_03.bvh" "$M/cmu/007_03.bvh" "$M/cmu/007_05.bvh" \
    "$M/cmu/007_08.bvh" --frames 500 --height 1.95 --girth 0.9
repeat near builtin "$M/cmu/007_03.bvh" "$M/cmu/007_05.bvh" "$M/cmu/002_07.bvh" --frames 300 \
    --distance 1.6
repeat close "${close_clips[@]}" --frames 300 --distance 2.0
repeat drift builtin --frames 500
# The climber with and without the back net (the only development clip that shows its back)
# and the side net.
posedrift -q eval synthetic "$M/cmu/001_08.bvh" --frames 500 --methods cpd,cpd-noback,cpd-noside \
    --repeats 5 --no-paper --json "$out/repeats_back.json" | tee "$out/repeats_back.md"
# The climber without and with the head and arms held once they leave the image, and at 2.0 m.
posedrift -q eval synthetic "$M/cmu/001_08.bvh" --frames 500 --methods cpd,cpd-nohold \
    --repeats 5 --no-paper --json "$out/repeats_hold.json" | tee "$out/repeats_hold.md"
posedrift -q eval synthetic "$M/cmu/001_08.bvh" --frames 300 --distance 2.0 \
    --methods cpd,cpd-nohold --repeats 5 --no-paper --json "$out/repeats_hold_close.json" \
    | tee "$out/repeats_hold_close.md"
utd_repeat() { posedrift -q eval utd "$data/utd-mhad" --sequences "${2%,}" --methods cpd,icp \
    --repeats 5 --json "$out/repeats_$1.json" | tee "$out/repeats_$1.md"; }
utd_repeat utd1 "$(for a in $(seq 1 27); do printf "a%d_s%d_t1," "$a" $(( a % 4 + 1 )); done)"
utd_repeat utd2 "$(for a in $(seq 1 27); do for s in 1 2 3 4; do printf "a%d_s%d_t2," "$a" "$s"
    done; done)"
# How much of the error the labels cause: the tracker, with a perfect forest, true labels.
python "$here/benchmarks/label_oracle.py" builtin "$M/cmu/002_05.bvh" "$M/cmu/002_07.bvh" \
    "$M/cmu/002_10.bvh" "$M/cmu/001_08.bvh" --frames 500 | tee "$out/label_oracle.md"
# How the previous skeleton is carried into the next frame, against the true joint motion.
python "$here/benchmarks/carried_joints_figure.py" "$M/cmu/002_07.bvh" "$out/carried_joints.png" \
    --frames 300 | tee "$out/carried_joints.md"
}

smooth() {
# Every method's joints smoothed in time (--smooth 0.1 s: a recording analysed after the
# fact), on the development and held-out clips, the first UTD-MHAD trials, and over five
# point samples on the development clips and the built-in motion (drift); then with two
# frames' latency (--smooth-lag 0.067: a live stream).
posedrift -q eval synthetic builtin "$M/cmu/002_05.bvh" "$M/cmu/002_07.bvh" "$M/cmu/002_10.bvh" \
    "$M/cmu/001_08.bvh" --frames 500 --methods "$methods" --smooth 0.1 \
    --json "$out/smooth_dev.json" | tee "$out/smooth_dev.md"
posedrift -q eval synthetic "$M/cmu-original-skeleton/131_03.bvh" "$M/cmu/007_03.bvh" \
    "$M/cmu/007_05.bvh" "$M/cmu/007_08.bvh" --frames 500 --methods "$methods" --smooth 0.1 \
    --json "$out/smooth_heldout.json" | tee "$out/smooth_heldout.md"
first=$(for a in $(seq 1 27); do printf "a%d_s%d_t1," "$a" $(( a % 4 + 1 )); done)
posedrift -q eval utd "$data/utd-mhad" --sequences "${first%,}" --methods "$methods" \
    --smooth 0.1 --json "$out/smooth_utd.json" | tee "$out/smooth_utd.md"
posedrift -q eval synthetic builtin "$M/cmu/002_05.bvh" "$M/cmu/002_07.bvh" "$M/cmu/002_10.bvh" \
    "$M/cmu/001_08.bvh" --frames 500 --methods cpd,icp --repeats 5 --smooth 0.1 --no-paper \
    --json "$out/smooth_repeats_dev.json" | tee "$out/smooth_repeats_dev.md"
posedrift -q eval synthetic builtin --frames 500 --methods cpd,icp --repeats 5 --smooth 0.1 \
    --no-paper --json "$out/smooth_repeats_drift.json" | tee "$out/smooth_repeats_drift.md"
# The same smoothing with two frames' latency (a live stream, posedrift.tracking.LiveSmoother).
posedrift -q eval synthetic builtin "$M/cmu/002_05.bvh" "$M/cmu/002_07.bvh" "$M/cmu/002_10.bvh" \
    "$M/cmu/001_08.bvh" --frames 500 --methods "$methods" --smooth 0.1 --smooth-lag 0.067 \
    --json "$out/live_dev.json" | tee "$out/live_dev.md"
posedrift -q eval utd "$data/utd-mhad" --sequences "${first%,}" --methods "$methods" \
    --smooth 0.1 --smooth-lag 0.067 --json "$out/live_utd.json" | tee "$out/live_utd.md"
posedrift -q eval synthetic builtin "$M/cmu/002_05.bvh" "$M/cmu/002_07.bvh" "$M/cmu/002_10.bvh" \
    "$M/cmu/001_08.bvh" --frames 500 --methods cpd,icp --repeats 5 --smooth 0.1 \
    --smooth-lag 0.067 --no-paper --json "$out/live_repeats_dev.json" \
    | tee "$out/live_repeats_dev.md"
}

speed() {
# Speed of the tracker, per stage, one core: the person alone, in a room, and at 640 x 480.
posedrift -q bench track --frames 300 --repeats 3 --json "$out/bench_track.json" | tee "$out/bench_track.md"
posedrift -q bench track --frames 300 --repeats 3 --room --json "$out/bench_track_room.json" \
    | tee "$out/bench_track_room.md"
posedrift -q bench track --frames 300 --repeats 3 --room --camera d435 --distance 2.0 \
    --json "$out/bench_track_vga.json" | tee "$out/bench_track_vga.md"
}

case "$part" in
    all) tables; repeats; smooth; speed ;;
    tables) tables ;;
    repeats) repeats ;;
    smooth) smooth ;;
    speed) speed ;;
esac
# The tables that compare runs (per clip, per view, drift, spread, the targets), from
# every JSON in OUT so far: after "tables" and "repeats" side by side, the later one's
# summary is the whole one.
python "$here/benchmarks/results_summary.py" "$out" > "$out/summary.md" 2>/dev/null
