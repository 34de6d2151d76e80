#!/usr/bin/env bash
# `make wheel-check`: build langpref's sdist and wheel, check the wheel holds no benchmark code, install it with only
# the core into a fresh venv (as a lab would: torch 2.13.0 first, then the wheel, with the known-good constraints),
# and smoke-test it there: import, --help, --version, `langpref import` + `langpref train` on a tiny plain recording,
# and the one-line message of each command that needs an extra which is not installed (simulators, study, LeRobot,
# figures, videos). Writes build/wheel-check/install.json (time and size of the fresh core install). About 2-3 min.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
PY=${PY:-python3}
OUT=$ROOT/build/wheel-check
export HF_HUB_OFFLINE=1 TOKENIZERS_PARALLELISM=false MUJOCO_GL=egl PYOPENGL_PLATFORM=egl

rm -rf "$OUT" && mkdir -p "$OUT/work"
echo "wheel-check: building the sdist and the wheel (python -m build)"
.venv/bin/python -m build --outdir "$OUT/dist" . >"$OUT/build.log" 2>&1 || { tail -30 "$OUT/build.log"; exit 1; }
WHEEL=$(ls "$OUT"/dist/langpref-*.whl)
echo "wheel-check: $(basename "$WHEEL") ($(du -k "$WHEEL" | cut -f1) kB); installing the core into a fresh venv"
# benchmarks live in benchmarks/ at the repository root: none of their code may ship in the wheel
.venv/bin/python - "$WHEEL" <<'PY' || { echo "wheel-check: FAILED: benchmark code in the wheel" >&2; exit 1; }
import re, sys, zipfile
names = zipfile.ZipFile(sys.argv[1]).namelist()
bench = [n for n in names if n.startswith("benchmarks/") or re.search(r"(^|/)[^/]*bench[^/]*\.py$", n)]
print(f"wheel-check: {len(names)} files in the wheel, no benchmark code" if not bench else f"benchmark code: {bench}")
sys.exit(1 if bench else 0)
PY

start=$(date +%s%N)
"$PY" -m venv "$OUT/venv"
V=$OUT/venv/bin
pip_quiet() { "$V/pip" install --quiet --disable-pip-version-check "$@" 2>>"$OUT/pip.log" || { tail "$OUT/pip.log"; exit 1; }; }
pip_quiet torch==2.13.0
pip_quiet -c requirements/constraints.txt "$WHEEL"
secs=$(( ($(date +%s%N) - start) / 1000000 ))e-3
mb=$(du -sm "$OUT/venv" | cut -f1)
"$V/python" - "$secs" "$mb" "$(basename "$WHEEL")" >"$OUT/install.json" <<'PY'
import json, platform, sys
from importlib.metadata import distributions
secs, mb, wheel = float(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
print(json.dumps({"wheel": wheel, "install_s": round(secs, 1), "venv_mb": mb, "packages": len(list(distributions())),
                  "python": platform.python_version()}))
PY
echo "wheel-check: fresh core install: $(cat "$OUT/install.json")"

fail() { echo "wheel-check: FAILED: $*" >&2; exit 1; }
cd "$OUT/work"  # away from the source tree: everything below uses the installed wheel

"$V/python" - <<'PY' || fail "the core venv is not what the core should be"
import importlib, importlib.util
import langpref
for m in ("langpref.cli", "langpref.dataset.importer", "langpref.dataset.frames", "langpref.model.train",
          "langpref.model.evaluate", "langpref.improve", "langpref.reward", "langpref.reward.saved", "langpref.propose",
          "langpref.feedback", "langpref.tasks", "langpref.tasks.gym", "langpref.extras"):
    importlib.import_module(m)
assert langpref.__file__.find("site-packages") > 0, langpref.__file__
extra = [m for m in ("metaworld", "robosuite", "mujoco", "fastapi", "uvicorn", "ray", "pyarrow", "matplotlib", "av")
         if importlib.util.find_spec(m)]
assert not extra, f"extras' packages in a core install: {extra}"
print(f"wheel-check: import langpref {langpref.__version__} (core only) ok")
PY

"$V/langpref" --help >/dev/null || fail "langpref --help"
version=$("$V/langpref" --version)
[[ $version == "langpref $("$V/python" -c 'import langpref; print(langpref.__version__)')" ]] || fail "--version: $version"
echo "wheel-check: $version; --help ok"
"$V/langpref" tasks >/dev/null || fail "langpref tasks"

"$V/python" "$ROOT/.ci/tiny_recording.py" rec
"$V/langpref" import rec/recording --task rec/task.toml --out data --json >import.json 2>import.log \
  || { cat import.log; fail "langpref import"; }
"$V/langpref" train --data data --out model --epochs 2 --finetune-epochs 1 --json >train.json 2>train.log \
  || { tail -5 train.log; fail "langpref train"; }
"$V/python" -c "import json; s = json.load(open('train.json')); assert s['best_val_accuracy'] >= 0, s" \
  || fail "train summary"
echo "wheel-check: import + train on a tiny plain recording ok ($(cat train.json))"

# a command that needs a missing extra: exit status 2 and one line naming the extra
expect_extra() {
  local extra=$1; shift
  set +e; "$V/langpref" "$@" >/dev/null 2>err.txt; local rc=$?; set -e
  [[ $rc == 2 && $(wc -l <err.txt) == 1 ]] && grep -qF "pip install 'langpref[$extra]'" err.txt \
    || { cat err.txt; fail "langpref $* (rc $rc): expected one line naming langpref[$extra]"; }
  echo "wheel-check: langpref $1 ... -> $(cat err.txt)"
}
expect_extra metaworld generate --env metaworld --out gen-mw --num-trajectories 4 --workers 2
expect_extra robosuite generate --env robosuite --out gen-rs --num-trajectories 4
expect_extra study study serve --model model --data data --db study.db
expect_extra lerobot import "$ROOT/tests/fixtures/lerobot/tiny" --task rec/task.toml --out lerobot-data
expect_extra plots visualize --model model --data data --out latent.png
clip=$ROOT/tests/fixtures/lerobot/tiny/videos/observation.images.front/chunk-000/file-000.mp4
cp -r rec/recording rec-video && for f in rec-video/*.npz; do cp "$clip" "${f%.npz}.mp4"; done  # episodes with videos
expect_extra video import rec-video --task rec/task.toml --out video-data
echo "wheel-check: ok"
