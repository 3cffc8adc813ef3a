#!/usr/bin/env bash
# Smoke test of the accuracy study (scripts/accuracy/run.sh --quick, docs/accuracy.md): the
# fire scene (data/vdb/densityAndHeat.vdb with its heat grid as temperature), its Monte
# Carlo reference, the three presets baked and compared, the plot and the tables written
# between the study markers of a scratch accuracy.md.
#   tests/accuracy/study_smoke_test.sh SOURCE_DIR BUILD_DIR SCRATCH_DIR
# Exit 77 (skipped) without python3-matplotlib. About 30 s on 2 cores.
set -euo pipefail
NAME=study_smoke_test
SRC=$1; BUILD=$2; W=$3/$NAME
/usr/bin/python3 -c "import matplotlib" 2>/dev/null || { echo "$NAME: SKIP: python3-matplotlib is not installed"; exit 77; }
rm -rf "$W"; mkdir -p "$W/docs"
printf '# Accuracy\n\nText kept.\n\n<!-- study:begin -->\nold\n<!-- study:end -->\n\nTail kept.\n' > "$W/docs/accuracy.md"
LPM_BUILD_DIR=$BUILD bash "$SRC/scripts/accuracy/run.sh" --quick --scenes fire --out "$W/out" --docs "$W/docs"
/usr/bin/python3 - "$W" <<'PY'
import json, math, os, sys
w = sys.argv[1]
rows = [json.loads(l) for l in open(os.path.join(w, "out", "results.jsonl"))]
assert [r["setting"] for r in rows] == ["preview", "default", "production"], rows
for r in rows:
    for k in ("band0_corrected", "band12_rms", "image_l1", "block_l1", "seconds", "peak_rss_mib"):
        assert math.isfinite(r[k]) and r[k] >= 0, (r["setting"], k, r[k])
    assert 0.9 < r["image_ratio"] < 1.1, (r["setting"], r["image_ratio"])
# The presets are ordered in error (the --verify estimates and the voxel errors).
v = [r["verify"]["error"] for r in rows]
assert v[0] > v[1] > v[2], v
assert rows[0]["band0_rms"] > rows[2]["band0_rms"], [r["band0_rms"] for r in rows]
doc = open(os.path.join(w, "docs", "accuracy.md")).read()
assert doc.startswith("# Accuracy\n\nText kept.") and doc.rstrip().endswith("Tail kept."), doc[:200]
assert "old" not in doc and "| fire |" in doc and "study_fire.png" in doc, doc
assert os.path.getsize(os.path.join(w, "docs", "accuracy", "study_fire.png")) > 5000
assert os.path.getsize(os.path.join(w, "docs", "accuracy", "fire_images.png")) > 500
print("study_smoke_test: ok: verify", ["%.4f" % x for x in v])
PY
