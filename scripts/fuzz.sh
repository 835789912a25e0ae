#!/usr/bin/env bash
# The long fuzz campaign (docs/reliability.md): the Rust readers' proptest properties
# (crates/lgi-core/tests/reader_fuzz.rs: OBJ, glTF, model files with recomputed checksums) and
# the Python API's hypothesis tests (tests/test_fuzz.py), with a budget far above the test
# command's, then the tally of generated inputs per target and outcome. Any panic, crash,
# non-finite output or silently accepted nonsense fails a property, so the script's exit
# status is the campaign's verdict.
#
#   bash scripts/fuzz.sh                     # default budget (2-3 minutes on 2 cores)
#   RUST_CASES=20000 PY_EXAMPLES=5000 bash scripts/fuzz.sh
#
# Python needs lgi installed (the test command's virtualenv, $LGI_TEST_VENV or .venv-test, is
# used when present; else the python on PATH).
set -euo pipefail
cd "$(dirname "$0")/.."
RUST_CASES="${RUST_CASES:-4000}"
PY_EXAMPLES="${PY_EXAMPLES:-1000}"
VENV="${LGI_TEST_VENV:-.venv-test}"
if [ -f "$VENV/bin/activate" ]; then
  # shellcheck disable=SC1091
  . "$VENV/bin/activate"
fi
out="$(mktemp -d)"
start=$(date +%s)

echo "== rust readers: $RUST_CASES cases per property"
LGI_FUZZ_TALLY="$out/rust.txt" PROPTEST_CASES="$RUST_CASES" \
  cargo test --release -p lgi-core --test reader_fuzz
rust_s=$(( $(date +%s) - start ))

echo "== python API: $PY_EXAMPLES examples per test"
(cd tests && LGI_FUZZ_EXAMPLES="$PY_EXAMPLES" LGI_FUZZ_REPORT="$out/python.json" \
  python -m pytest -q -p no:cacheprovider test_fuzz.py)
total_s=$(( $(date +%s) - start ))

python - "$out" "$rust_s" "$total_s" <<'EOF'
import collections, json, sys
out, rust_s, total_s = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
tally = collections.defaultdict(collections.Counter)
for line in open(f"{out}/rust.txt"):
    target, outcome = line.split()
    tally["rust " + target][outcome] += 1
for target, outcomes in json.load(open(f"{out}/python.json")).items():
    tally["python " + target].update(outcomes)
print(f"\n{'target':36} {'inputs':>8}  outcomes")
for target in sorted(tally):
    c = tally[target]
    print(f"{target:36} {sum(c.values()):8}  " + ", ".join(f"{k} {v}" for k, v in sorted(c.items())))
total = sum(sum(c.values()) for c in tally.values())
print(f"{'total':36} {total:8}  every property held: 0 panics, 0 crashes, 0 non-finite outputs,"
      " 0 silently accepted nonsense")
print(f"time: rust {rust_s} s, all {total_s} s")
EOF
rm -rf "$out"
