#!/usr/bin/env bash
# The "own robot" example end to end: record (a script that does not use langpref), import, train, check the model
# reads the bank's unseen test phrasings, then improvement and reward learning with synthetic humans who speak the
# task's bank, and one participant through both studies over HTTP on the recorded videos. Each step is skipped
# when its output exists. Numbers land in results/own_robot/ (see docs/results.md).
set -euo pipefail
cd "$(dirname "$0")/../.."
BIN=${BIN:-.venv/bin}
REC=data/own_robot_recording DATA=data/own_robot MODEL=models/own_robot OUT=results/own_robot
mkdir -p "$OUT"
test -d "$REC" || "$BIN/python" examples/own_robot/record.py --out "$REC" --episodes 200 --seed 0
test -f "$DATA/meta.json" || "$BIN/langpref" import "$REC" --task examples/own_robot/task.toml --out "$DATA" --seed 0
"$BIN/langpref" inspect "$DATA" --json > "$OUT/inspect.json"
test -f "$MODEL/config.json" || "$BIN/langpref" train --data "$DATA" --out "$MODEL" --json > "$OUT/train.json"
"$BIN/langpref" evaluate --model "$MODEL" --data "$DATA" --split test --json > "$OUT/evaluate.json"
"$BIN/langpref" experiment improve --env drawer-open --data "$DATA" --model "$MODEL" --out "$OUT/improve" --json \
    > "$OUT/improve.json"
"$BIN/langpref" experiment reward --env drawer-open --data "$DATA" --model "$MODEL" --out "$OUT/reward" --json \
    > "$OUT/reward.json"
"$BIN/python" examples/own_robot/study_check.py --model "$MODEL" --data "$DATA" > "$OUT/study_check.json"
echo "results in $OUT/ (improve/improve.png, reward/reward.png, study_check.json)"
